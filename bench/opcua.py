"""cncd's OPC UA server measured from outside: the update latency from the motion loop to a
subscribed client (p50, p99), the server's CPU at rest and during a job, and a job's underruns
and late cycles with N clients subscribed.

A fresh cncd (the sim card, real time) with `service.opcua` on a free port. This process is
both a plain control-socket subscriber (the `progress` topic: the motion loop's report, on the
socket within a millisecond) and one asyncua client; N-1 more clients subscribe from a second
process. Each is subscribed to the channel's X and Y positions, its state and the program's
line at the publishing interval asked. A job of circles
runs (X changes at every report); for each X value the OPC UA clients receive, the latency is
its arrival time less the arrival of the progress event that carried it. The server's CPU is
its process's utime + stime over the interval, in % of one core.

    python bench/opcua.py [--clients 10] [--publish-ms 50] [--rest-s 10] [--turns 12]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from asyncua import Client  # noqa: E402
from daemon_helpers import children_of, start_cncd, start_run  # noqa: E402

TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * TICK_S


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def config(tmp: Path, port: int, publish_ms: float) -> Path:
    data = yaml.safe_load((REPO / "config/xy_table.yaml").read_text())
    data["service"] = {"opcua": {"endpoint": f"opc.tcp://127.0.0.1:{port}/phcnc",
                                 "min_publish_ms": publish_ms}}
    path = tmp / "bench.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def circles(tmp: Path, turns: int) -> Path:
    program = tmp / "circles.nc"
    program.write_text("G21 G90 G17 F1500\nG1 X10 Y0\n"
                       + "G2 X10 Y0 I-10 J0\n" * turns + "G1 X0 Y0\nM2\n")
    return program


class ProgressTimes(threading.Thread):
    """The control socket's progress events: X position -> first arrival (monotonic)."""

    def __init__(self, path: str) -> None:
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_UNIX)
        self.sock.connect(path)
        self.sock.sendall(b'{"id":1,"cmd":"subscribe","topics":["progress"]}\n')
        self.times: dict[float, list[float]] = {}  # X -> every arrival carrying it

    def run(self) -> None:
        reader = self.sock.makefile("rb")
        for line in reader:
            now = time.monotonic()
            event = json.loads(line)
            if event.get("event") == "progress" and event.get("position_mm"):
                self.times.setdefault(round(float(event["position_mm"][0]), 6), []).append(now)

    def latency_s(self, arrived_s: float, x: float) -> float | None:
        """From the last report of x before the client heard of it (circles pass an X
        again each turn: the report that carried this value is the latest one before)."""
        before = [t for t in self.times.get(x, ()) if t <= arrived_s]
        return arrived_s - before[-1] if before else None


class Watcher:
    def __init__(self) -> None:
        self.arrivals: list[tuple[float, float]] = []  # (monotonic, X)
        self.x_node: Any = None

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        if node == self.x_node and val is not None:
            self.arrivals.append((time.monotonic(), round(float(val), 6)))


async def subscribe(endpoint: str, publish_ms: float) -> tuple[Client, Watcher]:
    client = Client(endpoint)
    await client.connect()
    ns = await client.get_namespace_array()
    mt, ma = ns.index("http://opcfoundation.org/UA/MachineTool/"), ns.index(
        "http://opcfoundation.org/UA/Machinery/")
    own = ns.index("urn:phcnc:opcua")
    machine = (await (await client.nodes.objects.get_child(f"{ma}:Machines")).get_children())[0]
    channel = await machine.get_child([f"{mt}:Monitoring", f"{own}:Channel1"])
    watcher = Watcher()
    watcher.x_node = await channel.get_child(f"{own}:ActualPositionX")
    nodes = [watcher.x_node, await channel.get_child(f"{own}:ActualPositionY"),
             await channel.get_child(f"{mt}:ChannelState"),
             await machine.get_child([f"{mt}:Production", f"{mt}:ActiveProgram",
                                      f"{own}:LineNumber"])]
    sub = await client.create_subscription(publish_ms, watcher)
    await sub.subscribe_data_change(nodes)
    return client, watcher


async def measure(args: argparse.Namespace, daemon: Any, endpoint: str,
                  program: Path) -> dict[str, Any]:
    server = next(pid for pid in children_of(daemon.proc.pid)
                  if b"opcua.main" in Path(f"/proc/{pid}/cmdline").read_bytes())
    one = [await subscribe(endpoint, args.publish_ms)]
    await asyncio.sleep(1.0)
    c0, d0, t0 = cpu_s(server), cpu_s(daemon.proc.pid), time.monotonic()
    await asyncio.sleep(args.rest_s)
    rest_pct = 100 * (cpu_s(server) - c0) / (time.monotonic() - t0)
    daemon_rest_pct = 100 * (cpu_s(daemon.proc.pid) - d0) / (time.monotonic() - t0)
    await one[0][0].disconnect()
    baseline, _ = await job(daemon, program, server)  # the server up, no client
    # One client measures here; the others subscribe from a process of their own, so their
    # notifications load the server and not the measuring client's event loop.
    others = subprocess.Popen([sys.executable, __file__, "--sit", endpoint, "--clients",
                               str(args.clients - 1), "--publish-ms", str(args.publish_ms)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL)
    assert others.stdout is not None and others.stdout.readline().strip() == b"subscribed"
    clients = [await subscribe(endpoint, args.publish_ms)]
    progress = ProgressTimes(daemon.socket_path)
    progress.start()
    await asyncio.sleep(1.0)
    final, job_pct = await job(daemon, program, server)
    await asyncio.sleep(0.5)
    latencies = [lat for _, w in clients for t, x in w.arrivals
                 if (lat := progress.latency_s(t, x)) is not None]
    for client, _ in clients:
        await client.disconnect()
    others.kill()  # by its pid
    others.wait()
    lat_ms = 1e3 * np.array(latencies)
    stats = {"p50": round(float(np.percentile(lat_ms, 50)), 1),
             "p99": round(float(np.percentile(lat_ms, 99)), 1),
             "max": round(float(lat_ms.max()), 1)} if lat_ms.size else {}
    return {"clients": args.clients, "publish_ms": args.publish_ms,
            "latency_ms": {**stats, "samples": int(lat_ms.size),
                           "reports": sum(len(v) for v in progress.times.values())},
            "cncd_cpu_pct_at_rest": round(daemon_rest_pct, 2),
            "server_cpu_pct": {"rest_one_client": round(rest_pct, 2),
                               f"job_{args.clients}_clients": round(job_pct, 2)},
            "job_no_client": {k: baseline.get(k) for k in KEYS},
            f"job_{args.clients}_clients": {k: final.get(k) for k in KEYS},
            "load_average": os.getloadavg()[0]}


KEYS = ("event", "underruns", "late_cycles", "motion_time_s")


async def job(daemon: Any, program: Path, server: int) -> tuple[dict[str, Any], float]:
    """Run the program through cncd; its final event and the server's CPU meanwhile (%)."""
    run = start_run(daemon, program)
    c0, t0 = cpu_s(server), time.monotonic()
    while run.poll() is None:
        await asyncio.sleep(0.05)
    pct = 100 * (cpu_s(server) - c0) / (time.monotonic() - t0)
    final = json.loads(run.stdout.read().strip().splitlines()[-1])  # type: ignore[union-attr]
    if final.get("event") == "fault":
        daemon.cncctl("reset")
    return final, pct


async def sit(endpoint: str, count: int, publish_ms: float) -> None:
    """--sit: count subscribed clients until standard input closes (the measuring process
    kills it by pid)."""
    clients = [await subscribe(endpoint, publish_ms) for _ in range(count)]
    print("subscribed", flush=True)
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
    for client, _ in clients:
        await client.disconnect()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=10)
    ap.add_argument("--publish-ms", type=float, default=50.0)
    ap.add_argument("--rest-s", type=float, default=10.0)
    ap.add_argument("--turns", type=int, default=12)
    ap.add_argument("--sit", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.sit:
        asyncio.run(sit(args.sit, args.clients, args.publish_ms))
        return 0
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        port = free_port()
        daemon = start_cncd(tmp, "--config", str(config(tmp, port, args.publish_ms)))
        try:
            deadline = time.monotonic() + 120
            while True:
                try:
                    socket.create_connection(("127.0.0.1", port), 0.2).close()
                    break
                except OSError:
                    assert time.monotonic() < deadline, "no OPC UA server"
                    time.sleep(0.2)
            assert daemon.cncctl("reset").returncode == 0, "reset refused"
            endpoint = f"opc.tcp://127.0.0.1:{port}/phcnc"
            figures = asyncio.run(measure(args, daemon, endpoint, circles(tmp, args.turns)))
        finally:
            daemon.proc.terminate()  # cncd stops its OPC UA server by pid
            daemon.proc.wait(timeout=30)
            daemon.notify.sock.close()
    print(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
