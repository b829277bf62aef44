"""cncd under load: status latency with 100 clients polling at 20 Hz during a run,
underruns of that run, restart-to-READY time, and SIGTERM-to-standstill time.

Each status client connects, asks and reads the reply (what `cncctl status` does, without
starting a Python interpreter per request), every 50 ms, over a fresh connection each time.
The clients run in 4 processes of 25 threads; latency is measured in the client.

    python bench/daemon.py [--clients 100] [--hz 20] [--program nc_programs/butterfly.nc]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from daemon_helpers import CNCCTL, start_cncd, stop  # noqa: E402


def _poll(path: str, hz: float, until: float, out: list[float]) -> None:
    period = 1.0 / hz
    next_t = time.monotonic()
    while time.monotonic() < until:
        t0 = time.monotonic()
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
                s.settimeout(5.0)
                s.connect(path)
                s.sendall(b'{"id": 1, "cmd": "status"}\n')
                line = s.makefile("rb").readline()
            if json.loads(line).get("ok"):
                out.append(time.monotonic() - t0)
            else:
                out.append(float("nan"))
        except OSError:
            out.append(float("nan"))
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))


def _client_process(path: str, threads: int, hz: float, duration_s: float, q: mp.Queue) -> None:
    until = time.monotonic() + duration_s
    results: list[list[float]] = [[] for _ in range(threads)]
    workers = [threading.Thread(target=_poll, args=(path, hz, until, r)) for r in results]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    q.put([x for r in results for x in r])


def status_under_load(tmp: Path, clients: int, hz: float, program: Path) -> dict:
    d = start_cncd(tmp, name="load")
    try:
        d.cncctl("reset")
        run = subprocess.Popen([*CNCCTL, "run", str(program), "--json", "--socket",
                                d.socket_path], stdout=subprocess.PIPE, text=True)
        time.sleep(0.3)
        q: mp.Queue = mp.Queue()
        procs = [mp.Process(target=_client_process, args=(d.socket_path, clients // 4, hz,
                                                          5.0, q)) for _ in range(4)]
        for p in procs:
            p.start()
        latencies = [x for _ in procs for x in q.get()]
        for p in procs:
            p.join()
        out, _ = run.communicate(timeout=60)
        final = json.loads(out.splitlines()[-1])
    finally:
        stop(d)
    lat = np.array(latencies)
    ok = lat[~np.isnan(lat)]
    return {"requests": len(lat), "failed": int(np.isnan(lat).sum()),
            "p50_ms": float(np.percentile(ok, 50) * 1e3), "p99_ms": float(np.percentile(ok, 99)
                                                                          * 1e3),
            "max_ms": float(ok.max() * 1e3), "run": final["event"],
            "underruns": final["underruns"], "late_cycles": final["late_cycles"],
            "min_fifo_ms": final["min_fifo_ms"]}


def restart_to_ready(tmp: Path, runs: int) -> list[float]:
    times = []
    for i in range(runs):
        t0 = time.monotonic()
        d = start_cncd(tmp, name=f"ready{i}")
        times.append(d.notify.times("READY=1")[0] - t0)
        stop(d)
    return times


def sigterm_to_standstill(tmp: Path, program: Path, runs: int) -> list[tuple[float, float]]:
    """(SIGTERM -> the job's final event at the client, SIGTERM -> daemon exit) per run."""
    out = []
    for i in range(runs):
        d = start_cncd(tmp, name=f"term{i}")
        try:
            d.cncctl("reset")
            run = subprocess.Popen([*CNCCTL, "run", str(program), "--json", "--socket",
                                    d.socket_path], stdout=subprocess.PIPE, text=True)
            assert run.stdout is not None
            while True:
                event = json.loads(run.stdout.readline())
                if event["event"] == "progress" and event["executed_s"] > 0.5:
                    break
            t0 = time.monotonic()
            os.kill(d.proc.pid, signal.SIGTERM)
            for line in run.stdout:
                if json.loads(line)["event"] in ("aborted", "done", "fault"):
                    break
            t_final = time.monotonic() - t0
            d.proc.wait(timeout=30)
            out.append((t_final, time.monotonic() - t0))
            run.wait(timeout=10)
        finally:
            stop(d)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, default=100)
    ap.add_argument("--hz", type=float, default=20.0)
    ap.add_argument("--program", default=str(REPO / "nc_programs/butterfly.nc"))
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        load = status_under_load(tmp, args.clients, args.hz, Path(args.program))
        print(f"status with {args.clients} clients at {args.hz:g} Hz during a run: "
              f"{load['requests']} requests, {load['failed']} failed, p50 {load['p50_ms']:.2f} "
              f"ms, p99 {load['p99_ms']:.2f} ms, max {load['max_ms']:.1f} ms; the run: "
              f"{load['run']}, underruns {load['underruns']}, late cycles "
              f"{load['late_cycles']}, lowest FIFO {load['min_fifo_ms']} ms")
        ready = restart_to_ready(tmp, args.runs)
        print(f"start to READY over {args.runs} starts: median {np.median(ready):.2f} s, "
              f"max {max(ready):.2f} s")
        term = sigterm_to_standstill(tmp, Path(args.program), args.runs)
        finals = [a for a, _ in term]
        exits = [b for _, b in term]
        print(f"SIGTERM mid-run to the job's last event (at rest): median {np.median(finals):.3f}"
              f" s, max {max(finals):.3f} s; to the daemon's exit: median "
              f"{np.median(exits):.3f} s, max {max(exits):.3f} s")


if __name__ == "__main__":
    main()
