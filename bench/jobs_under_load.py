"""Jobs through cncd on every backend, quiet and under load: faults, underruns, late cycles,
the lowest card FIFO, the daemon's CPU during the jobs, and the idle daemon's CPU.

For each backend (the sim card; the serial card and the CANopen drives on their simulated
peers, each in its own process on a pseudo-terminal), one cncd owns the drive; N airfoil and
N butterfly jobs are sent with `cncctl run --socket`, under each load in turn:

- quiet: nothing else running;
- cpu2+io: `stress-ng --cpu 2 --io 1` (two CPU hogs and one I/O hog);
- heavy: `stress-ng --cpu 4 --io 2 --vm 2 --vm-bytes 128M` (load average about 8).

The goal for each row: 0 faults, 0 underruns, the lowest FIFO never under half its high-water
mark. `cpu %` is the daemon process's CPU over the jobs' wall time (the motion loop runs in it;
the interpreter and generator are its children and not counted), at the config's T = 1 ms.
The idle CPU is the daemon's over 10 s, 5 s after `reset`, before any job.

    python bench/jobs_under_load.py [--jobs 20] [--backends sim serial canopen]
        [--loads quiet cpu2+io heavy] [--markdown]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from daemon_helpers import CNCCTL, start_cncd, stop  # noqa: E402

PROGRAMS = ("nc_programs/naca2415.nc", "nc_programs/butterfly.nc")
LOADS = {"quiet": [], "cpu2+io": ["--cpu", "2", "--io", "1"],
         "heavy": ["--cpu", "4", "--io", "2", "--vm", "2", "--vm-bytes", "128M"]}
CONFIGS = {"sim": "xy_table", "serial": "serial", "canopen": "canopen"}
OPTION_KEY = {"serial": "port", "canopen": "channel"}
IDLE_S = 10.0
IDLE_SETTLE_S = 5.0
BACK_TO_START = Path(tempfile.gettempdir()) / "phcnc-bench-back-to-start.nc"


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_peer(backend: str) -> tuple[subprocess.Popen | None, str | None]:
    if backend == "sim":
        return None, None
    peer = subprocess.Popen([*CNCCTL, "simdrive", backend], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    assert peer.stdout is not None
    return peer, peer.stdout.readline().strip()


def write_config(backend: str, device: str | None, folder: Path) -> Path:
    source = REPO / "config" / f"{CONFIGS[backend]}.yaml"
    data = yaml.safe_load(source.read_text())
    if device is not None:
        data["drive"]["options"][OPTION_KEY[backend]] = device
    path = folder / f"{backend}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def run_job(socket_path: str, program: str) -> dict[str, Any]:
    done = subprocess.run([*CNCCTL, "run", str(REPO / program), "--socket", socket_path,
                           "--json"], capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL)
    lines = [json.loads(x) for x in done.stdout.splitlines() if x.startswith("{")]
    final = lines[-1] if lines else {"event": "none", "message": done.stderr.strip()}
    final["exit"] = done.returncode
    return final


def load_processes(load: str) -> subprocess.Popen | None:
    if not LOADS[load]:
        return None
    if shutil.which("stress-ng") is None:
        sys.exit("stress-ng is needed for the loaded rows (Debian: apt-get install stress-ng)")
    proc = subprocess.Popen(["stress-ng", *LOADS[load], "--quiet"], start_new_session=True)
    time.sleep(2.0)  # the hogs up to speed
    return proc


def stop_load(proc: subprocess.Popen | None) -> None:
    if proc is None:
        return
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def bench_backend(backend: str, loads: list[str], jobs: int, folder: Path) -> list[dict]:
    peer, device = start_peer(backend)
    rows = []
    try:
        config = write_config(backend, device, folder)
        daemon = start_cncd(folder, "--config", str(config), name=f"cncd-{backend}")
        try:
            reset = daemon.cncctl("reset")
            assert reset.returncode == 0, reset.stderr
            time.sleep(IDLE_SETTLE_S)  # the sim card's clock sleeps 2 s after the table rests
            t0, c0 = time.monotonic(), cpu_s(daemon.proc.pid)
            time.sleep(IDLE_S)
            idle_pct = 100 * (cpu_s(daemon.proc.pid) - c0) / (time.monotonic() - t0)
            for load in loads:
                hog = load_processes(load)
                try:
                    rows.append(bench_load(daemon, backend, load, jobs) | {"idle_cpu_pct":
                                                                           idle_pct})
                finally:
                    stop_load(hog)
                if rows[-1]["faults"]:  # a faulted daemon latches: reset for the next load
                    daemon.cncctl("reset")
        finally:
            stop(daemon)
    finally:
        if peer is not None:
            peer.kill()
            peer.wait()
    return rows


def bench_load(daemon: Any, backend: str, load: str, jobs: int) -> dict[str, Any]:
    finals = []
    t0, c0 = time.monotonic(), cpu_s(daemon.proc.pid)
    for _ in range(jobs):
        for program in PROGRAMS:
            final = run_job(daemon.socket_path, program)
            finals.append(final)
            if final.get("event") != "done":
                print(f"  {backend}/{load} {program}: {final.get('event')} "
                      f"{final.get('message', '')}", file=sys.stderr)
                daemon.cncctl("reset")
                run_job(daemon.socket_path, str(BACK_TO_START))  # the programs start at 0, 0
    wall_s = time.monotonic() - t0
    done = [f for f in finals if f.get("event") == "done"]
    fifo = [f["min_fifo_ms"] for f in finals if f.get("min_fifo_ms") is not None]
    late = [f.get("late_cycles", 0) for f in finals]
    return {"backend": backend, "load": load, "jobs": len(finals), "done": len(done),
            "faults": len(finals) - len(done),
            "underruns": sum(f.get("underruns", 0) for f in finals),
            "late_cycles_total": sum(late), "late_cycles_max": max(late, default=0),
            "lowest_fifo_ms": min(fifo, default=float("nan")),
            "cpu_pct": 100 * (cpu_s(daemon.proc.pid) - c0) / wall_s,
            "load_average": os.getloadavg()[0]}


def markdown(rows: list[dict]) -> str:
    out = ["| backend | load | done | faults | underruns | late cycles (total / max a job) "
           "| lowest FIFO (ms) | daemon CPU during jobs | idle daemon CPU |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['backend']} | {r['load']} (load avg {r['load_average']:.1f}) | "
                   f"{r['done']}/{r['jobs']} | {r['faults']} | {r['underruns']} | "
                   f"{r['late_cycles_total']} / {r['late_cycles_max']} | "
                   f"{r['lowest_fifo_ms']:.0f} | {r['cpu_pct']:.0f} % | "
                   f"{r['idle_cpu_pct']:.2f} % |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=20, help="jobs of each program per row")
    ap.add_argument("--backends", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    ap.add_argument("--loads", nargs="+", default=list(LOADS), choices=list(LOADS))
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    rows = []
    BACK_TO_START.write_text("G21 G90\nG0 X0 Y0\nM2\n")
    with tempfile.TemporaryDirectory() as tmp:
        for backend in args.backends:
            rows += bench_backend(backend, args.loads, args.jobs, Path(tmp))
    print(f"{os.cpu_count()} CPUs; running as uid {os.getuid()}", file=sys.stderr)
    print(markdown(rows) if args.markdown else json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
