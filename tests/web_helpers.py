"""Helpers for the web panel's tests: a real cncd with `--http` on a free loopback port, and
HTTP and WebSocket clients (aiohttp) run to completion from a test."""

from __future__ import annotations

import asyncio
import json
import socket
import time
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import aiohttp
from daemon_helpers import REPO, Cncd, running_cncd

CONFIG = str(REPO / "config" / "xy_table.yaml")  # this tree's config, whatever is installed


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def web_cncd(tmp_path: Path, *extra: str, **kw: Any) -> Iterator[tuple[Cncd, str]]:
    """cncd with its panel (READY=1 is sent once the panel serves); (daemon, base URL)."""
    port = free_port()
    with running_cncd(tmp_path, "--config", CONFIG, "--http", f"127.0.0.1:{port}",
                      *extra, **kw) as daemon:
        yield daemon, f"http://127.0.0.1:{port}"


def run(coro: Awaitable[Any]) -> Any:
    return asyncio.run(coro)  # type: ignore[arg-type]


async def http(method: str, url: str, **kw: Any) -> tuple[int, Any]:
    async with aiohttp.ClientSession() as s, s.request(method, url, **kw) as r:
        body = await r.read()
        try:
            return r.status, json.loads(body)
        except ValueError:
            return r.status, body


def rpc_http(base: str, method: str, params: dict[str, Any] | None = None,
             token: str | None = None) -> dict[str, Any]:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    status, body = run(http("POST", f"{base}/api/rpc", headers=headers, json={
        "jsonrpc": "2.0", "id": 1, "method": method, "params": params or {}}))
    assert status == 200, body
    return body


class Ws:
    """One WebSocket: calls, and every pushed notification kept with its arrival time."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        self.ws = ws
        self.pushed: list[tuple[float, dict[str, Any]]] = []
        self._id = 0
        self._replies: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self._task = asyncio.create_task(self._read())

    async def _read(self) -> None:
        async for msg in self.ws:
            if msg.type != aiohttp.WSMsgType.TEXT:
                break
            m = json.loads(msg.data)
            if "method" in m:
                self.pushed.append((time.monotonic(), m))
            elif m.get("id") in self._replies:
                self._replies.pop(m["id"]).set_result(m)

    async def call(self, method: str, **params: Any) -> dict[str, Any]:
        self._id += 1
        future = asyncio.get_running_loop().create_future()
        self._replies[self._id] = future
        await self.ws.send_json({"jsonrpc": "2.0", "id": self._id, "method": method,
                                 "params": params})
        return await asyncio.wait_for(future, 15.0)

    def statuses(self, since: float = 0.0) -> list[dict[str, Any]]:
        return [m["params"] for t, m in self.pushed if m["method"] == "status" and t >= since]

    async def wait_for(self, test: Callable[[dict[str, Any]], bool],
                       timeout_s: float = 20.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for _, m in reversed(self.pushed):
                if m["method"] == "status":
                    if test(m["params"]):
                        return m["params"]
                    break
            await asyncio.sleep(0.01)
        last = self.statuses()[-1:] or [None]
        raise AssertionError(f"status never matched in {timeout_s} s; last {last[0]}")


async def open_ws(base: str, token: str | None = None) -> tuple[aiohttp.ClientSession, Ws]:
    session = aiohttp.ClientSession()
    ws = await session.ws_connect(base.replace("http", "ws", 1) + "/ws")
    if token is not None:
        await ws.send_json({"jsonrpc": "2.0", "id": 0, "method": "auth",
                            "params": {"token": token}})
        reply = await ws.receive_json(timeout=5)
        assert reply.get("result") == {"authenticated": True}, reply
    return session, Ws(ws)
