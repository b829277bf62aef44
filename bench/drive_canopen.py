"""CANopen bench: the airfoil on the simulated CiA 402 peer over the slcan pty, at T = 1 and 2 ms.

For each period, one `cncctl simdrive canopen` peer process and N runs of the program through
the Runtime API (the motion loop, the SYNC cycle thread and the CAN receive thread in this
process). Reports the SYNC -> TPDO1 round trip (p50, p99, max, pooled over the runs), TPDO1s
later than one period, late SYNC cycles, the MotionResult's late motion cycles and underruns,
and the CPU share of the motion process (getrusage over each run's wall time) and of the peer.

    python bench/drive_canopen.py [--runs 10] [--periods 0.001 0.002] [--program FILE]
"""

from __future__ import annotations

import argparse
import os
import resource
import select
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


def write_config(period_s: float, folder: Path) -> Path:
    data = yaml.safe_load((REPO / "config" / "canopen.yaml").read_text())
    data["sample_period_s"] = period_s
    data["name"] = f"canopen_{period_s * 1e3:g}ms"
    path = folder / f"canopen_{period_s * 1e3:g}ms.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def cpu_ticks_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def bench_period(period_s: float, runs: int, program: str, folder: Path) -> dict[str, Any]:
    cfg_path = write_config(period_s, folder)
    config = load_config(str(cfg_path))
    peer = subprocess.Popen([sys.executable, "-m", "controller.operator.cli", "simdrive",
                             "canopen", "--config", str(cfg_path)], stdout=subprocess.PIPE,
                            text=True, cwd=REPO)
    rows: list[dict[str, Any]] = []
    rtt: list[np.ndarray] = []
    try:
        ready, _, _ = select.select([peer.stdout], [], [], 20.0)
        if not ready:
            raise SystemExit("simdrive did not start")
        channel = peer.stdout.readline().strip()
        config = config.with_drive_options({"channel": channel})
        for _ in range(runs):
            drive = make_drive(config, realtime=True)
            peer_cpu0_s = cpu_ticks_s(peer.pid)
            r0 = resource.getrusage(resource.RUSAGE_SELF)
            t0_s = time.monotonic()
            result = Runtime(program, config, RuntimeOptions(drive=drive)).run()
            wall_s = time.monotonic() - t0_s
            r1 = resource.getrusage(resource.RUSAGE_SELF)
            cpu_s = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
            stats = drive.link_stats()
            rtt.append(drive.rtt_samples_ms())
            rows.append({"outcome": result.outcome.value, "message": result.message,
                         "late_cycles": result.late_cycles, "underruns": result.underruns,
                         "cpu_share": cpu_s / wall_s,
                         "peer_cpu_share": (cpu_ticks_s(peer.pid) - peer_cpu0_s) / wall_s,
                         "wall_s": wall_s, "motion_s": result.motion_time_s, **stats})
    finally:
        peer.kill()
        peer.wait(timeout=10)
    pooled = np.concatenate(rtt) if rtt else np.zeros(0)
    return {"period_ms": period_s * 1e3, "runs": rows, "rtt_ms": pooled}


def summary(res: dict[str, Any]) -> list[str]:
    rows, rtt, period_ms = res["runs"], res["rtt_ms"], res["period_ms"]
    done = sum(r["outcome"] == "done" for r in rows)
    cpu = np.array([r["cpu_share"] for r in rows]) * 100
    peer_cpu = np.array([r["peer_cpu_share"] for r in rows]) * 100
    return [
        f"{period_ms:g} ms", f"{done}/{len(rows)}",
        f"{np.percentile(rtt, 50):.2f} / {np.percentile(rtt, 99):.2f} / {rtt.max():.2f}",
        f"{int((rtt > period_ms).sum())}/{len(rtt)}",
        str(sum(int(r.get("missed_tpdos", 0)) for r in rows)),
        str(sum(int(r.get("late_syncs", 0)) for r in rows)),
        str(sum(r["late_cycles"] for r in rows)), str(sum(r["underruns"] for r in rows)),
        f"{cpu.mean():.0f} % (max {cpu.max():.0f} %)", f"{peer_cpu.mean():.0f} %",
        f"{np.mean([r['bringup_s'] for r in rows]) * 1e3:.0f} ms",
    ]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--periods", type=float, nargs="+", default=[0.001, 0.002])
    parser.add_argument("--program", default=str(REPO / "nc_programs" / "naca2415.nc"))
    args = parser.parse_args()
    head = ["T", "done", "SYNC->TPDO1 p50 / p99 / max ms", "TPDO1 > T", "missed TPDO1",
            "late SYNC", "late motion cycles", "underruns", "motion process CPU", "peer CPU",
            "bring-up"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    with tempfile.TemporaryDirectory() as tmp:
        for period_s in args.periods:
            res = bench_period(period_s, args.runs, args.program, Path(tmp))
            for r in res["runs"]:
                if r["outcome"] != "done":
                    print(f"  T={period_s * 1e3:g} ms: {r['outcome']}: {r['message']}",
                          file=sys.stderr)
            lines.append("| " + " | ".join(summary(res)) + " |")
    print(f"{args.runs} runs of {Path(args.program).name} per period, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
