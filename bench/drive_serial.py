"""Serial-card bench: the airfoil on the simulated serial card at T = 1 ms and 2 ms, N runs each.

Each run starts a fresh `cncctl simdrive serial` (its own process, on a pty) and runs the
program through the Runtime API in this process, which is the motion process. Reported:

- round trip: a status request written by the motion process -> the matching status reply
  decoded by the backend's reader thread (SerialCard.link_stats(); one request every
  poll_period_s, 20 ms by default). It spans the host's write, the pty, the card's wake-up and
  reply, and the host reader thread's wake-up. p50 / p99 / max over all requests of all runs.
- late motion cycles and card underruns (from each MotionResult), lowest FIFO level;
- CPU share of the motion process: getrusage(RUSAGE_SELF) user+system time over the run's wall
  time (the interpreter, generator and card processes are not counted).

    python bench/drive_serial.py [--runs 10] [--periods 0.001 0.002] [--load]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from controller.config import load_config  # noqa: E402
from controller.runtime.processes import Runtime, RuntimeOptions  # noqa: E402
from drivers.registry import make_drive  # noqa: E402

HOG = "x = 0\nwhile True:\n    x = (x + 1) % 1000003\n"


def config_file(period_s: float, folder: Path) -> Path:
    """config/serial.yaml with sample_period_s replaced."""
    data = yaml.safe_load((REPO / "config" / "serial.yaml").read_text())
    data["sample_period_s"] = period_s
    path = folder / f"serial_{period_s * 1e3:g}ms.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def one_run(cfg_path: Path, program: str) -> dict[str, Any]:
    peer = subprocess.Popen([sys.executable, "-m", "controller.operator.cli", "simdrive",
                             "serial", "--config", str(cfg_path)], cwd=REPO,
                            stdout=subprocess.PIPE, text=True)
    try:
        port = peer.stdout.readline().strip()
        config = load_config(str(cfg_path)).with_drive_options({"port": port})
        drive = make_drive(config, realtime=True)
        before = resource.getrusage(resource.RUSAGE_SELF)
        t0_s = time.monotonic()
        result = Runtime(program, config, RuntimeOptions(drive=drive)).run()
        wall_s = time.monotonic() - t0_s
        after = resource.getrusage(resource.RUSAGE_SELF)
    finally:
        peer.kill()
        peer.wait(timeout=10)
        peer.stdout.close()
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    stats = drive.link_stats()
    return {"outcome": result.outcome.value, "message": result.message,
            "rtt_s": stats["rtt_s"], "late": result.late_cycles, "underruns": result.underruns,
            "min_fifo_ms": result.min_fifo_ms, "cpu_share": cpu_s / wall_s,
            "crc_errors": stats["crc_errors"], "max_gap_s": stats["max_status_gap_s"],
            "final": result.final_position_mm}


def row(period_s: float, runs: list[dict[str, Any]]) -> str:
    rtt_ms = np.concatenate([np.asarray(r["rtt_s"]) for r in runs]) * 1e3
    cpu = np.array([r["cpu_share"] for r in runs]) * 100
    done = sum(r["outcome"] == "done" for r in runs)
    return (f"{period_s * 1e3:>4g} ms | {done:>2}/{len(runs):<2} | {len(rtt_ms):>5} | "
            f"{np.percentile(rtt_ms, 50):6.3f} {np.percentile(rtt_ms, 99):6.3f} "
            f"{rtt_ms.max():6.3f} | {sum(r['late'] for r in runs):>4} "
            f"{max(r['late'] for r in runs):>3} | {sum(r['underruns'] for r in runs):>4} | "
            f"{min(r['min_fifo_ms'] for r in runs):6.1f} | {cpu.mean():5.1f} {cpu.max():5.1f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--periods", type=float, nargs="+", default=[0.001, 0.002])
    ap.add_argument("--program", default=str(REPO / "nc_programs" / "naca2415.nc"))
    ap.add_argument("--load", action="store_true", help="one CPU hog per core during the runs")
    args = ap.parse_args()
    hogs = [subprocess.Popen([sys.executable, "-c", HOG])
            for _ in range(os.cpu_count() or 2)] if args.load else []
    lines = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for period_s in args.periods:
                cfg_path = config_file(period_s, Path(tmp))
                runs = []
                for i in range(args.runs):
                    runs.append(one_run(cfg_path, args.program))
                    r = runs[-1]
                    print(f"T={period_s * 1e3:g} ms run {i + 1}: {r['outcome']} "
                          f"{r['message'] or ''} late={r['late']} underruns={r['underruns']} "
                          f"final={r['final']} max status gap {r['max_gap_s'] * 1e3:.1f} ms",
                          file=sys.stderr, flush=True)
                lines.append(row(period_s, runs))
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    print(f"serial card bench: {args.runs} runs of {Path(args.program).name} per period"
          f"{', both cores loaded' if args.load else ''}")
    print("   T    | done  | rtts  | round trip ms p50 p99 max | late sum max | underr | "
          "minFIFO ms | CPU % mean max")
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
