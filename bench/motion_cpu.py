"""Motion-process CPU per second of motion at T = 1 ms on each backend, and virtual time's speed.

    python bench/motion_cpu.py [--copies 5] [--runs 2] [--backends sim virtual canopen serial]
                               [--code DIR]

The program is nc_programs/naca2415.nc's airfoil `--copies` times in a row (bench/
long_programs.py's airfoil_xN). Each run goes through the Runtime API in this process, which is
then the motion process (the motion loop and the drive's own threads: the sim card's clock, the
CANopen SYNC and receive threads, the serial reader); the interpreter and generator are
processes of their own and not counted. Backends:

- sim: config/xy_table.yaml, the sim card clocked by its own thread in real time;
- virtual: the same in virtual time (`cncctl run --virtual-time`): the sim card is clocked by
  the loop as fast as the producers allow; its real-time factor is motion time / CPU time;
- canopen: config/canopen.yaml against a `cncctl simdrive canopen` peer process (slcan pty);
- serial: config/serial.yaml against a `cncctl simdrive serial` peer process (pty).

A virtual-time run first pays the imports and caches, outside the figures. Per backend:
motion-process CPU (getrusage user + system over the runs, set-up, settling and bring-up
included) per second of motion and motion time over it, the wall time and the CPU over it (a
share of one core), the late cycles and underruns, the runs done.
--code DIR imports the controller from another checkout (a before/after comparison).
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

REPO = Path(__file__).resolve().parents[1]
PEER_CONFIG = {"canopen": "canopen.yaml", "serial": "serial.yaml"}
PEER_OPTION = {"canopen": "channel", "serial": "port"}


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def start_peer(backend: str, cfg_path: Path) -> tuple[subprocess.Popen, str]:
    """A `cncctl simdrive` peer process and the port it answers on."""
    peer = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "controller.operator.cli",
            "simdrive",
            backend,
            "--config",
            str(cfg_path),
        ],
        stdout=subprocess.PIPE,
        text=True,
        cwd=os.environ["PYTHONPATH"],
    )
    assert peer.stdout is not None
    return peer, peer.stdout.readline().strip()


def one_run(backend: str, program: Path) -> dict[str, Any]:
    from controller.config import load_config
    from controller.runtime.processes import Runtime, RuntimeOptions
    from drivers.registry import make_drive

    name = PEER_CONFIG.get(backend, "xy_table.yaml")
    cfg_path = REPO / "config" / name
    peer = None
    config = load_config(str(cfg_path))
    if backend in PEER_CONFIG:
        peer, port = start_peer(backend, cfg_path)
        config = config.with_drive_options({PEER_OPTION[backend]: port})
    try:
        virtual = backend == "virtual"
        drive = make_drive(config, realtime=not virtual)
        cpu0_s, t0_s = cpu_s(), time.monotonic()
        result = Runtime(
            str(program), config, RuntimeOptions(drive=drive, virtual_time=virtual)
        ).run()
        wall_s, used_s = time.monotonic() - t0_s, cpu_s() - cpu0_s
    finally:
        if peer is not None:
            peer.kill()  # the peer this run started, by its own handle
            peer.wait(timeout=10)
            assert peer.stdout is not None
            peer.stdout.close()
    return {
        "backend": backend,
        "outcome": result.outcome.value,
        "message": result.message,
        "motion_s": result.motion_time_s,
        "cpu_s": used_s,
        "wall_s": wall_s,
        "late": result.late_cycles,
        "underruns": result.underruns,
    }


def row(runs: list[dict[str, Any]]) -> str:
    motion_s = sum(r["motion_s"] for r in runs)
    cpu = sum(r["cpu_s"] for r in runs)
    wall_s = sum(r["wall_s"] for r in runs)
    done = sum(r["outcome"] == "done" for r in runs)
    per_s_ms = 1e3 * cpu / motion_s if motion_s else float("nan")
    rtf = motion_s / cpu if cpu else float("nan")
    return (
        f"| {runs[0]['backend']} | {done}/{len(runs)} | {motion_s:.1f} | {cpu:.2f} | "
        f"{per_s_ms:.0f} | {rtf:.0f} | {wall_s:.1f} | {100 * cpu / wall_s:.0f} % | "
        f"{sum(r['late'] for r in runs)} | {sum(r['underruns'] for r in runs)} |"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=5)
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument(
        "--backends",
        nargs="+",
        default=["sim", "virtual", "canopen", "serial"],
        choices=["sim", "virtual", "canopen", "serial"],
    )
    parser.add_argument("--code", default=str(REPO), help="checkout whose controller is run")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(args.code).resolve()))
    os.environ["PYTHONPATH"] = str(Path(args.code).resolve())  # the peers import it too
    sys.path.insert(1, str(REPO / "bench"))
    from long_programs import write_airfoil

    lines = [
        "| backend | done | motion (s) | motion CPU (s) | CPU per s of motion (ms) | motion / CPU "
        "| wall (s) | CPU / wall | late cycles | underruns |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        program = Path(tmp) / f"airfoil_x{args.copies}.nc"
        write_airfoil(program, args.copies)
        one_run("virtual", program)  # imports and caches paid once, outside the figures
        for backend in args.backends:
            runs = [one_run(backend, program) for _ in range(args.runs)]
            for r in runs:
                if r["outcome"] != "done":
                    print(f"  {backend}: {r['outcome']}: {r['message']}", file=sys.stderr)
            lines.append(row(runs))
    print(
        f"code: {args.code}; {args.runs} runs per backend of the airfoil x{args.copies}, "
        f"T = 1 ms; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}"
    )
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
