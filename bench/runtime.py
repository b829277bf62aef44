"""Runtime bench: N real-time `cncctl run --json` of the airfoil with both cores kept busy.

Reports per run and in summary: underruns (target 0), late motion cycles, lowest card FIFO
level (ms), time from launching `cncctl run` to the first executed frame (target < 0.5 s),
and the peak RSS of the interpreter, generator and motion processes.

    python bench/runtime.py [--runs 20] [--program nc_programs/naca2415.nc] [--no-load]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
HOG = "x = 0\nwhile True:\n    x = (x + 1) % 1000003\n"
CHURN = ("import time\nwhile True:\n    b = [bytearray(4096) for _ in range(2000)]\n"
         "    time.sleep(0.001)\n")


def start_load(n_cpus: int) -> list[subprocess.Popen]:
    """One CPU hog per core plus an allocation-churning process (the load a PC
    running other programs puts on a Python 1 kHz loop)."""
    procs = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(n_cpus)]
    procs.append(subprocess.Popen([sys.executable, "-c", CHURN]))
    return procs


def stop_load(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        p.terminate()
    for p in procs:
        p.wait(timeout=5)


def one_run(program: str, config: str | None = None) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "controller.operator.cli", "run", program, "--json"]
    cmd += ["--config", config] if config else []
    launched = time.time()
    out = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    events = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    final = events[-1] if events else {"event": "crash", "message": out.stderr[-300:]}
    first = final.get("first_motion_epoch_s")
    final["launch_to_motion_s"] = None if first is None else first - launched
    final["exit_code"] = out.returncode
    return final


def summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    def col(key: str) -> list[Any]:
        return [r.get(key) for r in runs if r.get(key) is not None]
    rss = [r.get("peak_rss_mb", {}) for r in runs]
    return {
        "runs": len(runs),
        "done": sum(r.get("event") == "done" for r in runs),
        "underruns_total": sum(col("underruns")),
        "late_cycles_max": max(col("late_cycles"), default=None),
        "late_cycles_total": sum(col("late_cycles")),
        "min_fifo_ms_lowest": min(col("min_fifo_ms"), default=None),
        "launch_to_motion_s_max": max(col("launch_to_motion_s"), default=None),
        "launch_to_motion_s_median": sorted(col("launch_to_motion_s"))[len(runs) // 2]
        if col("launch_to_motion_s") else None,
        "peak_rss_mb_max": {k: max((r.get(k, 0.0) for r in rss), default=0.0)
                            for k in ("interpreter", "generator", "motion")},
        "contour_error_um_max": max((r["contour_error_um"]["max"] for r in runs
                                     if "contour_error_um" in r), default=None),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--program", default="nc_programs/naca2415.nc")
    ap.add_argument("--no-load", action="store_true", help="do not load the cores")
    ap.add_argument("--config", help="machine configuration (default: the built-in one)")
    args = ap.parse_args()
    load = [] if args.no_load else start_load(os.cpu_count() or 2)
    runs: list[dict[str, Any]] = []
    try:
        for i in range(args.runs):
            r = one_run(args.program, args.config)
            runs.append(r)
            print(f"run {i + 1:2d}: {r.get('event')} exit {r['exit_code']} underruns "
                  f"{r.get('underruns')} late {r.get('late_cycles')} min_fifo "
                  f"{r.get('min_fifo_ms')} ms launch->motion {r['launch_to_motion_s']}",
                  file=sys.stderr, flush=True)
    finally:
        stop_load(load)
    print(json.dumps(summary(runs), indent=2))
    return 0 if all(r.get("event") == "done" and not r.get("underruns") for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
