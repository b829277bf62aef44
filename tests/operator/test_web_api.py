"""The web API against a real cncd (`--http`) on the sim card, from outside: HTTP requests and
WebSockets over real TCP, the panel a process of its own, every request through the control
socket. Status push rate, jobs, hold and resume, MDI, library, refusals, jog dead-man."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import time
from pathlib import Path

import pytest

pytest.importorskip("aiohttp")

from daemon_helpers import CNCD, REPO, children_of, running  # noqa: E402
from web_helpers import http, open_ws, rpc_http, run, web_cncd  # noqa: E402

NACA = (REPO / "nc_programs" / "naca2415.nc").read_bytes()


def test_status_pages_and_refusals(tmp_path: Path) -> None:
    with web_cncd(tmp_path) as (daemon, base):
        status, page = run(http("GET", base + "/"))
        assert status == 200 and b"E-STOP" in page
        status, body = run(http("GET", base + "/api/status"))
        assert status == 200 and body["state"] == "ESTOP"
        status, doc = run(http("GET", base + "/api/openapi.json"))
        assert {"mdi", "jog", "programs.preview", "queue.start_next"} <= set(
            doc["x-jsonrpc-methods"])
        # another site's page, a DNS-rebound name: refused before anything happens
        assert run(http("GET", base + "/api/status",
                        headers={"Origin": "http://evil.example"}))[0] == 403
        assert run(http("GET", base + "/api/status", headers={"Host": "evil.example"}))[0] == 403
        assert run(http("POST", base + "/api/rpc", data=b'{"jsonrpc":"2.0","id":1,'
                        b'"method":"reset"}', headers={"Origin": "http://evil.example"}))[0] \
            == 403
        assert daemon.status()["state"] == "ESTOP"  # the refused reset did nothing
        # a job is refused as the socket refuses it (e-stop latched), and nothing moves
        assert run(http("POST", base + "/api/programs/naca.nc", data=NACA))[0] == 200
        reply = rpc_http(base, "run", {"name": "naca.nc"})
        assert reply["error"]["data"]["reason"] == "estop"
        # bad requests get an error and change nothing
        assert rpc_http(base, "feed", {"percent": 200})["error"]["data"]["reason"] == "bad-field"
        assert rpc_http(base, "feed", {"percent": 50, "extra": 1})["error"]["code"] == -32602
        assert rpc_http(base, "nosuch")["error"]["code"] == -32601
        assert daemon.status()["feed_override_pct"] == 100.0
        for bad in ("..%2Fescape.nc", ".hidden", "a%2Fb", "x" * 101):
            assert run(http("POST", f"{base}/api/programs/{bad}", data=b"G0 X1\n"))[0] == 400
        assert run(http("POST", base + "/api/programs/big.nc",
                        data=b"G0 X1\n" * (3 << 20)))[0] == 413
        names = [p["name"] for p in run(http("GET", base + "/api/programs"))[1]["programs"]]
        assert names == ["naca.nc"]
        assert sorted(p.name for p in (daemon.state_dir / "programs").iterdir()) == ["naca.nc"]
        assert not (daemon.state_dir / "escape.nc").exists()


def test_a_job_pushed_at_25_hz_held_resumed_done(tmp_path: Path) -> None:
    async def scenario(base: str) -> None:
        session, ws = await open_ws(base)
        async with session:
            t0 = time.monotonic()
            await asyncio.sleep(1.0)
            idle = ws.statuses(since=t0 + 0.1)
            assert len(idle) >= 0.9 * 20 * 0.9, len(idle)  # >= 20 Hz idle too (timer-based)
            assert (await ws.call("reset"))["result"]["state"] == "IDLE"
            await ws.call("feed", percent=50)  # a longer run, to hold it midway
            seen = len(ws.pushed)
            job = (await ws.call("run", name="naca.nc"))["result"]
            assert job["job"] >= 1
            moving = await ws.wait_for(lambda s: s.get("source") == "progress"
                                       and s["state"] == "RUNNING" and (s["line"] or 0) > 0)
            t_run = time.monotonic()
            await asyncio.sleep(0.5)
            pushed = [s for s in ws.statuses(since=t_run) if s.get("source") == "progress"]
            assert len(pushed) >= 10, len(pushed)  # 20 Hz or more from the motion loop
            assert pushed[-1]["work_position_mm"] != moving["work_position_mm"]
            assert (await ws.call("hold"))["result"]["state"] in ("HOLDING", "HELD")
            held = await ws.wait_for(lambda s: s["state"] == "HELD")
            await asyncio.sleep(0.3)
            assert ws.statuses()[-1]["work_position_mm"] == held["work_position_mm"]
            await ws.call("resume")
            await ws.wait_for(lambda s: s["state"] == "IDLE", timeout_s=30)
            deadline = time.monotonic() + 10
            while not (finals := [m["params"] for _, m in ws.pushed[seen:]
                                  if m["method"] == "job" and m["params"].get("final")]):
                assert time.monotonic() < deadline, "no final job event"
                await asyncio.sleep(0.02)
            assert finals[0]["state"] == "done", finals
            await ws.call("feed", percent=100)

    with web_cncd(tmp_path) as (daemon, base):
        assert run(http("POST", base + "/api/programs/naca.nc", data=NACA))[0] == 200
        run(scenario(base))
        assert daemon.status()["last_job"]["state"] == "DONE"


def test_mdi_keeps_modes_and_is_checked_first(tmp_path: Path) -> None:
    async def scenario(base: str) -> None:
        session, ws = await open_ws(base)
        async with session:
            await ws.call("reset")
            assert "result" in await ws.call("mdi", text="G91 G1 X1 F600")
            await ws.wait_for(lambda s: s["state"] == "IDLE" and s["position_mm"]["x"] == 1.0)
            # G91, G1 and F600 kept: "X1" moves 1 mm further
            await ws.call("mdi", text="X1")
            await ws.wait_for(lambda s: s["state"] == "IDLE" and s["position_mm"]["x"] == 2.0)
            # a mistake names the MDI line and word, and nothing moves
            await ws.call("mdi", text="Y1\nX1 Q")
            await asyncio.sleep(1.0)
            rejected = [m["params"] for _, m in ws.pushed if m["method"] == "job"
                        and m["params"].get("final") and m["params"]["state"] == "rejected"]
            assert rejected and rejected[-1]["message"].startswith("MDI:2:"), rejected
            assert ws.statuses()[-1]["position_mm"] == {"x": 2.0, "y": 0.0}
            await ws.call("mdi", text="G90 G0 X0")  # the airfoil starts at X0 Y0
            await ws.wait_for(lambda s: s["state"] == "IDLE" and s["position_mm"]["x"] == 0.0)
            # refused while a job runs
            await ws.call("feed", percent=30)
            await ws.call("run", name="naca.nc")
            await ws.wait_for(lambda s: s["state"] == "RUNNING")
            busy = await ws.call("mdi", text="G0 X0")
            assert busy["error"]["data"]["reason"] == "busy"
            await ws.call("abort")
            await ws.wait_for(lambda s: s["state"] == "IDLE")
            await ws.call("feed", percent=100)
            await queue_job_by_job(ws)

    with web_cncd(tmp_path) as (_, base):
        run(http("POST", base + "/api/programs/naca.nc", data=NACA))
        run(http("POST", base + "/api/programs/step.nc", data=b"G91 G1 X1 F1200\nM2\n"))
        run(scenario(base))


async def queue_job_by_job(ws) -> None:  # noqa: ANN001
    """Two queued jobs, each started by hand; a name not in the library is refused."""
    assert (await ws.call("queue.add", name="nosuch.nc"))["error"]["data"]["reason"] == \
        "not-found"
    first = (await ws.call("queue.add", name="step.nc"))["result"]
    second = (await ws.call("queue.add", name="step.nc"))["result"]
    x0 = ws.statuses()[-1]["position_mm"]["x"]
    for n, entry in enumerate((first, second), start=1):
        started = (await ws.call("queue.start_next"))["result"]
        assert started["entry"]["id"] == entry["id"]
        await ws.wait_for(lambda s, n=n: s["state"] == "IDLE"
                          and abs(s["position_mm"]["x"] - (x0 + n)) < 1e-3)
        await asyncio.sleep(1.0)  # nothing starts the next job but the operator
        assert ws.statuses()[-1]["position_mm"]["x"] == pytest.approx(x0 + n, abs=1e-3)
    queue = (await ws.call("queue.list"))["result"]["queue"]
    assert [e["state"] for e in queue] == ["done", "done"]
    assert (await ws.call("queue.start_next"))["error"]["data"]["reason"] == "empty"
    assert (await ws.call("queue.clear_finished"))["result"]["queue"] == []


def test_continuous_jog_stops_when_the_connection_drops_or_the_lease_runs_out(
        tmp_path: Path) -> None:
    async def jog_then(base: str, drop: bool) -> tuple[float, float]:
        session, ws = await open_ws(base)
        await ws.call("reset")
        start_x = ws.statuses()[-1]["position_mm"]["x"]
        reply = await ws.call("jog", axis="x", direction=1, feed_mm_min=600)
        assert "result" in reply, reply

        async def renew() -> None:  # as the page does while the button is held
            while True:
                await asyncio.sleep(0.2)
                assert (await ws.call("jog_renew"))["result"]["renewed"]
        renewing = asyncio.create_task(renew())
        await ws.wait_for(lambda s: s["position_mm"]["x"] > start_x + 0.5)
        renewing.cancel()
        if drop:
            await session.close()  # the page closed, the network dropped
        else:
            await asyncio.sleep(1.0)  # no jog_renew: the lease (0.5 s) runs out
        stopped_at = time.monotonic()
        if drop:
            session, ws = await open_ws(base)
        await ws.wait_for(lambda s: s["state"] == "IDLE", timeout_s=5)
        x_idle = ws.statuses()[-1]["position_mm"]["x"]
        await session.close()
        return time.monotonic() - stopped_at, x_idle - start_x

    with web_cncd(tmp_path) as (daemon, base):
        for drop in (True, False):
            took_s, moved_mm = run(jog_then(base, drop))
            # at 10 mm/s a jog left running for its 60 s time-out would cross the travel
            assert took_s < 2.0, took_s
            assert moved_mm < 25.0, moved_mm
        assert "aborted" in daemon.cncctl("log", "-n", "200").stdout


def test_token_rules(tmp_path: Path) -> None:
    # beyond the loopback without a token: cncd refuses to start, nothing listens
    done = subprocess.run([*CNCD, "--config", str(REPO / "config" / "xy_table.yaml"),
                           "--socket", str(tmp_path / "x.sock"), "--state-dir",
                           str(tmp_path / "x-state"), "--http", "0.0.0.0:1"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "needs a token" in done.stderr
    token = tmp_path / "token"
    token.write_text("s3cret-token-0123456789\n")
    token.chmod(0o644)
    done = subprocess.run([*CNCD, "--config", str(REPO / "config" / "xy_table.yaml"),
                           "--socket", str(tmp_path / "x.sock"), "--state-dir",
                           str(tmp_path / "x-state"), "--http", "127.0.0.1:1",
                           "--http-token-file", str(token)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "readable by others" in done.stderr
    token.chmod(0o600)

    async def ws_without_token(base: str) -> int | None:
        import aiohttp
        async with aiohttp.ClientSession() as s, s.ws_connect(
                base.replace("http", "ws", 1) + "/ws") as ws:
            await ws.send_json({"jsonrpc": "2.0", "id": 1, "method": "reset"})
            await ws.receive(timeout=5)
            return ws.close_code

    async def ws_with_token(base: str) -> str:
        session, ws = await open_ws(base, token="s3cret-token-0123456789")
        async with session:
            return (await ws.call("status"))["result"]["state"]

    with web_cncd(tmp_path, "--http-token-file", str(token)) as (daemon, base):
        assert run(http("GET", base + "/api/status"))[0] == 401
        assert run(http("GET", base + "/api/status",
                        headers={"Authorization": "Bearer wrong-token-0123456789"}))[0] == 401
        status, body = run(http("GET", base + "/api/status",
                                headers={"Authorization": "Bearer s3cret-token-0123456789"}))
        assert status == 200 and body["state"] == "ESTOP"
        assert run(ws_without_token(base)) == 4401
        assert daemon.status()["state"] == "ESTOP"  # the reset sent first did nothing
        assert run(ws_with_token(base)) == "ESTOP"


def test_the_panel_lives_and_dies_with_cncd(tmp_path: Path) -> None:
    with web_cncd(tmp_path) as (daemon, base):
        panel = children_of(daemon.proc.pid)
        assert len(panel) == 1
        daemon.proc.send_signal(signal.SIGKILL)
        daemon.proc.wait(timeout=10)
        assert not running(panel[0], wait_s=5.0), "the panel outlived a killed cncd"
    with web_cncd(tmp_path, name="second") as (daemon, base):
        panel = children_of(daemon.proc.pid)
        daemon.proc.send_signal(signal.SIGTERM)
        assert daemon.proc.wait(timeout=20) == 0
        assert not running(panel[0], wait_s=2.0)


def test_the_config_can_ask_for_the_panel(tmp_path: Path) -> None:
    from daemon_helpers import running_cncd
    from web_helpers import free_port

    port = free_port()
    config = tmp_path / "mill.yaml"
    config.write_text((REPO / "config" / "xy_table.yaml").read_text()
                      + f'\nservice:\n  http: "127.0.0.1:{port}"\n')
    with running_cncd(tmp_path, "--config", str(config)):
        status, body = run(http("GET", f"http://127.0.0.1:{port}/api/status"))
        assert status == 200 and body["state"] == "ESTOP"
