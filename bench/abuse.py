"""Attacks on a real cncd from an authorised local account: e-stop latency with many hostile
connections, status latency, late cycles of a job under attack, and the daemon's peak RSS.

Each row starts a fresh cncd (the sim card) in its own process, and attacker processes of
their own (one per 300 connections) open N hostile connections of one kind:
- silent: connect and say nothing;
- subscribers: subscribe to every topic, then never read;
- trickle: send one byte of a request every 0.5 s;
- flood: connect, send a status request, hang up, as fast as possible (4 threads in each of
  1 or 4 processes; the connections column is the number of processes).

Then it measures, 20 times each: the e-stop (connect to the e-stop socket until its answer
`{"ok": true, "state": "ESTOP"}`, then `reset`), and a status request on the control
socket. The job row runs the butterfly while 100 clients of each kind attack, and reports its
late cycles and underruns against the same job without attack.

    python bench/abuse.py [--counts 64 500 5000] [--flood-processes 1 4] [--markdown]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from daemon_helpers import CNCCTL, start_cncd, stop  # noqa: E402

from controller.operator.client import connect_unix, estop_socket_path  # noqa: E402

KINDS = ("silent", "subscribers", "trickle", "flood")
SAMPLES = 20


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class Attack:
    """N hostile connections of one kind, kept up (re-opened when the daemon closes one)
    until stop()."""

    def __init__(self, path: str, kind: str, n: int) -> None:
        self.path, self.kind, self.n = path, kind, n
        self.stop_flag = threading.Event()
        self.socks: list[socket.socket] = []
        self.threads: list[threading.Thread] = []

    def _open(self) -> socket.socket | None:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.setblocking(True)
        sock.settimeout(2.0)
        try:
            sock.connect(self.path)
            if self.kind == "subscribers":
                sock.sendall(b'{"id": 1, "cmd": "subscribe", "topics": ["state", "progress", '
                             b'"log"]}\n')
        except OSError:
            sock.close()
            return None
        return sock

    def start(self) -> None:
        if self.kind == "flood":
            for _ in range(4):
                t = threading.Thread(target=self._flood, daemon=True)
                t.start()
                self.threads.append(t)
            return
        deadline_s = time.monotonic() + 30.0
        while len(self.socks) < self.n and time.monotonic() < deadline_s:
            sock = self._open()  # refused when connecting too fast: tried again
            if sock is not None and self._answered_at_once(sock):
                self.socks.append(sock)
        if self.kind == "trickle":
            t = threading.Thread(target=self._trickle, daemon=True)
            t.start()
            self.threads.append(t)

    @staticmethod
    def _answered_at_once(sock: socket.socket) -> bool:
        """False (and closed) when the daemon refused the connection straight away."""
        sock.setblocking(False)
        try:
            time.sleep(0.0005)
            refused = sock.recv(1, socket.MSG_PEEK) is not None
        except BlockingIOError:
            refused = False
        except OSError:
            refused = True
        sock.setblocking(True)
        sock.settimeout(2.0)
        if refused:
            sock.close()
        return not refused

    def _trickle(self) -> None:
        text = b'{"id": 1, "cmd": "status"}'
        i = 0
        while not self.stop_flag.wait(0.5):
            for k, sock in enumerate(self.socks):
                try:
                    sock.send(text[i % len(text):i % len(text) + 1])
                except OSError:
                    fresh = self._open()
                    if fresh is not None:
                        sock.close()
                        self.socks[k] = fresh
            i += 1

    def _flood(self) -> None:
        while not self.stop_flag.is_set():
            sock = self._open()
            if sock is None:
                continue
            try:
                sock.sendall(b'{"id": 1, "cmd": "status"}\n')
            except OSError:
                pass
            sock.close()

    def stop(self) -> None:
        self.stop_flag.set()
        for t in self.threads:
            t.join(timeout=5)
        for sock in self.socks:
            sock.close()


class Attackers:
    """The hostile connections in processes of their own (a real attacker is not the operator's
    process; the daemon limits how often one process may connect): one process per 300
    connections, or `processes` flooding processes of 4 threads each. Stopped by pid."""

    def __init__(self, path: str, kind: str, n: int, processes: int = 1) -> None:
        count = processes if kind == "flood" else max(1, -(-n // 300))
        share = -(-n // count)
        self.procs = [subprocess.Popen([sys.executable, __file__, "--attack", kind, "--n",
                                        str(share), "--socket", path], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, text=True)
                      for _ in range(count)]
        self.opened = sum(int(p.stdout.readline().split()[1] or 0) for p in self.procs)

    def stop(self) -> None:
        for proc in self.procs:
            proc.terminate()
        for proc in self.procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def attack_process(kind: str, n: int, path: str) -> None:
    """Child: open the connections (up to 30 s), say how many, attack until SIGTERM."""
    attack = Attack(path, kind, n)
    attack.start()
    print(f"opened {len(attack.socks)}", flush=True)
    while True:  # SIGTERM's default action ends it, and the kernel closes its sockets
        time.sleep(3600)


def estop_ms(path: str) -> float:
    t0 = time.monotonic()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(10.0)
        connect_unix(sock, estop_socket_path(path), 10.0)  # as cncctl connects
        reply = json.loads(sock.makefile("rb").readline())
    assert reply.get("state") == "ESTOP", reply
    return (time.monotonic() - t0) * 1e3


def status_ms(path: str) -> float:
    t0 = time.monotonic()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(10.0)
        connect_unix(sock, path, 10.0)
        sock.sendall(b'{"id": 5, "cmd": "status"}\n')
        reply = json.loads(sock.makefile("rb").readline())
    assert reply.get("ok"), reply
    return (time.monotonic() - t0) * 1e3


def reset(path: str) -> None:
    done = subprocess.run([*CNCCTL, "reset", "--socket", path], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr


def latency_row(kind: str, n: int, folder: Path) -> dict[str, Any]:
    daemon = start_cncd(folder, name=f"cncd-{kind}-{n}")
    try:
        reset(daemon.socket_path)
        attack = Attackers(daemon.socket_path, kind, n, processes=n)
        time.sleep(1.0)
        estops, statuses, failed = [], [], {"estop": 0, "status": 0, "reset": 0}
        try:
            for _ in range(SAMPLES):
                for name, measure, out in (("estop", estop_ms, estops),
                                           ("status", status_ms, statuses)):
                    try:
                        out.append(measure(daemon.socket_path))
                    except (OSError, AssertionError, ValueError):
                        failed[name] += 1  # refused, timed out or unanswered
                try:
                    reset(daemon.socket_path)
                except (OSError, AssertionError, subprocess.TimeoutExpired):
                    failed["reset"] += 1
        finally:
            attack.stop()
        return {"kind": kind, "connections": n, "opened": attack.opened,
                "estop_ms_max": max(estops, default=float("nan")),
                "estop_ms_p50": float(np.median(estops)) if estops else float("nan"),
                "status_ms_p99": float(np.percentile(statuses, 99)) if statuses else float("nan"),
                "status_ms_max": max(statuses, default=float("nan")), "failed": failed,
                "daemon_rss_mb": rss_mb(daemon.proc.pid)}
    finally:
        stop(daemon)


def job_row(kind: str | None, folder: Path) -> dict[str, Any]:
    daemon = start_cncd(folder, name=f"cncd-job-{kind}")
    attack = None
    try:
        reset(daemon.socket_path)
        if kind is not None:
            attack = Attackers(daemon.socket_path, kind, 100)
            time.sleep(1.0)
        done = subprocess.run([*CNCCTL, "run", str(REPO / "nc_programs/butterfly.nc"), "--json",
                               "--socket", daemon.socket_path], capture_output=True, text=True,
                              timeout=120, stdin=subprocess.DEVNULL)
        lines = done.stdout.splitlines()
        final = json.loads(lines[-1]) if lines else {"event": done.stderr.strip()[:80]}
        return {"kind": kind or "none", "outcome": final.get("event"),
                "late_cycles": final.get("late_cycles"), "underruns": final.get("underruns"),
                "min_fifo_ms": final.get("min_fifo_ms"), "daemon_rss_mb": rss_mb(daemon.proc.pid)}
    finally:
        if attack is not None:
            attack.stop()
        stop(daemon)


def markdown(latency: list[dict], jobs: list[dict]) -> str:
    out = ["| attack | connections | e-stop p50 / max (ms) | status p99 / max (ms) | failed "
           "(e-stop / status / reset, of 20) | daemon peak RSS (MB) |", "|---|---|---|---|---|---|"]
    for r in latency:
        f = r["failed"]
        out.append(f"| {r['kind']} | {r['connections']} | {r['estop_ms_p50']:.1f} / "
                   f"{r['estop_ms_max']:.1f} | {r['status_ms_p99']:.1f} / "
                   f"{r['status_ms_max']:.1f} | {f['estop']} / {f['status']} / {f['reset']} | "
                   f"{r['daemon_rss_mb']:.0f} |")
    out += ["", "| attack during the butterfly (100 clients) | outcome | late cycles | underruns "
            "| lowest FIFO (ms) | daemon peak RSS (MB) |", "|---|---|---|---|---|---|"]
    for r in jobs:
        out.append(f"| {r['kind']} | {r['outcome']} | {r['late_cycles']} | {r['underruns']} | "
                   f"{r['min_fifo_ms']} | {r['daemon_rss_mb']:.0f} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", nargs="+", type=int, default=[64, 500, 5000])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--flood-processes", nargs="+", type=int, default=[1, 4])
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--attack", choices=KINDS, help=argparse.SUPPRESS)  # an attacker child
    ap.add_argument("--n", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--socket", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.attack:
        attack_process(args.attack, args.n, args.socket)
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))  # thousands of client sockets
    latency, jobs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            for n in args.counts if kind != "flood" else args.flood_processes:
                latency.append(latency_row(kind, n, Path(tmp)))
                print(f"{kind} {n}: done", file=sys.stderr)
        for kind in (None, *args.kinds):
            jobs.append(job_row(kind, Path(tmp)))
    print(f"{os.cpu_count()} CPUs, uid {os.getuid()}", file=sys.stderr)
    print(markdown(latency, jobs) if args.markdown else json.dumps(
        {"latency": latency, "jobs": jobs}, indent=1))


if __name__ == "__main__":
    main()
