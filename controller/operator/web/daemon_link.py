"""cncd's control socket from an asyncio loop: one connection, requests matched to replies by
id, pushed events handed to a callback. The web panel goes through it for everything, so the
daemon's own checks (who may connect, sizes, busy, e-stop, limits) apply to every request."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

from controller.operator.client import DaemonError, DaemonUnavailable

READ_LIMIT_BYTES = 16 << 20  # one reply line (a status, a log of 100 000 events)
REQUEST_TIMEOUT_S = 10.0

Event = Callable[[dict[str, Any]], None]


class DaemonLink:
    """One control-socket connection. `closed` is set when the daemon hangs up."""

    def __init__(self, path: str, on_event: Event | None = None) -> None:
        self.path = path
        self.on_event = on_event or (lambda event: None)
        self.closed = asyncio.Event()
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._pending: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self._next_id = 0
        self._task: asyncio.Task[None] | None = None
        self._send_lock = asyncio.Lock()

    async def open(self) -> DaemonLink:
        try:
            self._reader, self._writer = await asyncio.wait_for(
                asyncio.open_unix_connection(self.path, limit=READ_LIMIT_BYTES), 5.0)
        except (OSError, TimeoutError) as exc:
            raise DaemonUnavailable(f"no daemon on {self.path}: {exc}") from None
        self._task = asyncio.create_task(self._read_loop())
        return self

    async def request(self, cmd: str, payload: bytes = b"", **fields: Any) -> dict[str, Any]:
        """One request (the program text after it for `run`); its reply, or DaemonError."""
        if self._writer is None or self.closed.is_set():
            raise DaemonUnavailable("the daemon connection is closed")
        self._next_id += 1
        rid = self._next_id
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._pending[rid] = future
        line = json.dumps({"id": rid, "cmd": cmd, **fields}).encode() + b"\n"
        try:
            async with self._send_lock:  # a program's bytes follow its line, uninterrupted
                self._writer.write(line + payload)
                await self._writer.drain()
            reply = await asyncio.wait_for(future, REQUEST_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            raise DaemonUnavailable(f"daemon connection: {exc or 'no reply'}") from None
        finally:
            self._pending.pop(rid, None)
        if not reply.get("ok"):
            raise DaemonError(reply.get("error", "error"), reply.get("message", ""))
        return reply

    async def _read_loop(self) -> None:
        assert self._reader is not None
        try:
            while True:
                line = await self._reader.readline()
                if not line:
                    break
                try:
                    message = json.loads(line)
                except ValueError:
                    continue
                self._dispatch(message)
        except (OSError, ValueError, asyncio.LimitOverrunError):
            pass
        finally:
            self.closed.set()
            for future in self._pending.values():
                if not future.done():
                    future.set_exception(DaemonUnavailable("the daemon closed the connection"))

    def _dispatch(self, message: dict[str, Any]) -> None:
        rid = message.get("id")
        if "ok" in message and rid in self._pending:
            future = self._pending[rid]
            if not future.done():
                future.set_result(message)
        elif "ok" in message and rid is None and not message.get("ok"):
            # a refusal of the connection itself (framing, unauthorised): fails every request
            for future in self._pending.values():
                if not future.done():
                    future.set_result(message)
        elif "event" in message:
            self.on_event(message)

    async def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            try:
                await self._writer.wait_closed()
            except OSError:
                pass
        if self._task is not None:
            await asyncio.gather(self._task, return_exceptions=True)
