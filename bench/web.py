"""The web panel under 20 WebSocket subscribers during runs on the sim card: the status rate
each one gets, the latency from the motion loop to the client (the progress event's
CLOCK_MONOTONIC stamp, taken in the motion thread, against the client's clock on arrival),
the CPU of the panel's process and of cncd, the job's underruns and late cycles; the same
jobs without the panel for comparison; the panel's load time in headless Chromium.

    python bench/web.py [--clients 20] [--runs 3] [--program nc_programs/butterfly.nc]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import aiohttp
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))
from daemon_helpers import children_of, running_cncd  # noqa: E402
from web_helpers import CONFIG, free_port  # noqa: E402

from controller.operator.client import DaemonClient  # noqa: E402


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def subscriber(url: str, record: list[tuple[float, dict[str, Any]]],
                     stop: asyncio.Event) -> None:
    async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
        reader = asyncio.create_task(_read(ws, record))
        await stop.wait()
        reader.cancel()


async def _read(ws: aiohttp.ClientWebSocketResponse,
                record: list[tuple[float, dict[str, Any]]]) -> None:
    async for msg in ws:
        if msg.type != aiohttp.WSMsgType.TEXT:
            return
        now = time.monotonic()
        m = json.loads(msg.data)
        if m.get("method") == "status":
            record.append((now, m["params"]))


async def one_run(base: str, name: str, clients: int) -> dict[str, Any]:
    url = base.replace("http", "ws", 1) + "/ws"
    records: list[list[tuple[float, dict[str, Any]]]] = [[] for _ in range(clients)]
    stop = asyncio.Event()
    subs = [asyncio.create_task(subscriber(url, r, stop)) for r in records]
    async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
        await asyncio.sleep(0.5)
        await ws.send_json({"jsonrpc": "2.0", "id": 1, "method": "run", "params": {"name": name}})
        t0 = time.monotonic()
        final = None
        while final is None:
            m = json.loads((await ws.receive(timeout=300)).data)
            if m.get("id") == 1 and "error" in m:
                raise SystemExit(f"run refused: {m['error']}")
            if m.get("method") == "job" and m["params"].get("final"):
                final = m["params"]
        t1 = time.monotonic()
    await asyncio.sleep(0.2)
    stop.set()
    await asyncio.gather(*subs)
    rates, latencies = [], []
    for rec in records:
        during = [(t, s) for t, s in rec if t0 <= t <= t1]
        rates.append(len(during) / (t1 - t0))
        latencies += [t - s["t_mono"] for t, s in during if s.get("source") == "progress"]
    result = final.get("result") or {}
    return {"wall_s": t1 - t0, "rate_min_hz": min(rates), "rate_mean_hz": statistics.mean(rates),
            "latencies_s": latencies, "state": final["state"],
            "underruns": result.get("underruns"), "late_cycles": result.get("late_cycles")}


def reset(socket_path: str) -> None:
    with DaemonClient(socket_path) as c:
        c.request("reset")


def bench_panel(tmp: Path, program: Path, clients: int, runs: int) -> dict[str, Any]:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with running_cncd(tmp, "--config", CONFIG, "--http", f"127.0.0.1:{port}",
                      name="web") as daemon:
        panel_pid = children_of(daemon.proc.pid)[0]
        idle = idle_cpu(panel_pid, daemon.proc.pid)
        reset(daemon.socket_path)
        data = program.read_bytes()
        asyncio.run(_upload(base, program.name, data))
        rows = []
        for _ in range(runs):
            c_web, c_d = cpu_s(panel_pid), cpu_s(daemon.proc.pid)
            row = asyncio.run(one_run(base, program.name, clients))
            row["web_cpu_pct"] = 100 * (cpu_s(panel_pid) - c_web) / row["wall_s"]
            row["cncd_cpu_pct"] = 100 * (cpu_s(daemon.proc.pid) - c_d) / row["wall_s"]
            rows.append(row)
        load = panel_load(base)
    return {"rows": rows, "load_ms": load, "idle": idle}


def idle_cpu(panel_pid: int, daemon_pid: int, seconds: float = 10.0) -> tuple[float, float]:
    """CPU % of the panel and of cncd, idle, with no WebSocket open."""
    time.sleep(1.0)
    c_web, c_d, t0 = cpu_s(panel_pid), cpu_s(daemon_pid), time.monotonic()
    time.sleep(seconds)
    wall = time.monotonic() - t0
    return 100 * (cpu_s(panel_pid) - c_web) / wall, 100 * (cpu_s(daemon_pid) - c_d) / wall


async def _upload(base: str, name: str, data: bytes) -> None:
    async with aiohttp.ClientSession() as s, s.post(f"{base}/api/programs/{name}",
                                                    data=data) as r:
        assert r.status == 200, await r.text()


def bench_without_panel(tmp: Path, program: Path, runs: int) -> list[dict[str, Any]]:
    rows = []
    with running_cncd(tmp, "--config", CONFIG, name="plain") as daemon:
        reset(daemon.socket_path)
        for _ in range(runs):
            c_d, t0 = cpu_s(daemon.proc.pid), time.monotonic()
            with DaemonClient(daemon.socket_path, timeout_s=300) as c:
                data = program.read_bytes()
                c.request("run", data, name=program.name, program_bytes=len(data), follow=True)
                final = next(m for m in c.messages(300)
                             if m.get("event") in ("done", "fault", "aborted", "rejected"))
            wall = time.monotonic() - t0
            rows.append({"state": final["event"], "underruns": final.get("underruns"),
                         "late_cycles": final.get("late_cycles"),
                         "cncd_cpu_pct": 100 * (cpu_s(daemon.proc.pid) - c_d) / wall})
    return rows


def panel_load(base: str, times: int = 5) -> list[float]:
    """Navigation start to the first status shown, in headless Chromium (ms)."""
    try:
        from selenium import webdriver
    except ImportError:
        return []
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage"):
        options.add_argument(arg)
    driver = webdriver.Chrome(options=options, service=webdriver.ChromeService(
        executable_path="/usr/bin/chromedriver"))
    out = []
    try:
        for _ in range(times):
            driver.get(base + "/")
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                mark = driver.execute_script(
                    "const m = performance.getEntriesByName('first-status');"
                    "return m.length ? m[0].startTime : null;")
                if mark is not None:
                    out.append(float(mark))
                    break
                time.sleep(0.02)
    finally:
        driver.quit()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--program", type=Path, default=REPO / "nc_programs" / "butterfly.nc")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        panel = bench_panel(Path(tmp), args.program, args.clients, args.runs)
        plain = bench_without_panel(Path(tmp), args.program, args.runs)
    lat_ms = 1e3 * np.array([x for r in panel["rows"] for x in r["latencies_s"]])
    print(f"{args.clients} WebSocket subscribers, {args.runs} runs of {args.program.name} "
          "on the sim card")
    for r in panel["rows"]:
        print(f"  {r['state']}: {r['wall_s']:.2f} s, status per client min "
              f"{r['rate_min_hz']:.1f} Hz mean {r['rate_mean_hz']:.1f} Hz, panel CPU "
              f"{r['web_cpu_pct']:.1f} %, cncd CPU {r['cncd_cpu_pct']:.1f} %, underruns "
              f"{r['underruns']}, late cycles {r['late_cycles']}")
    print(f"  latency motion loop -> client: p50 {np.percentile(lat_ms, 50):.1f} ms, p99 "
          f"{np.percentile(lat_ms, 99):.1f} ms, max {lat_ms.max():.1f} ms "
          f"({len(lat_ms)} samples)")
    for r in plain:
        print(f"  without the panel: {r['state']}, cncd CPU {r['cncd_cpu_pct']:.1f} %, "
              f"underruns {r['underruns']}, late cycles {r['late_cycles']}")
    print(f"  idle, no WebSocket open: panel CPU {panel['idle'][0]:.1f} %, cncd CPU "
          f"{panel['idle'][1]:.1f} %")
    if panel["load_ms"]:
        loads = panel["load_ms"]
        print(f"  panel load (navigation to the first status shown), headless Chromium: median "
              f"{statistics.median(loads):.0f} ms, max {max(loads):.0f} ms ({len(loads)} loads)")


if __name__ == "__main__":
    main()
