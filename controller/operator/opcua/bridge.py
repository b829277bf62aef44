"""cncd's control socket read as a client, the way `cncctl status --watch` does: subscribed to
its state and progress events, with a status request after each state change (and a slow
poll while nothing is pushed), every change handed to the view at once."""

from __future__ import annotations

import asyncio
import json
import logging
import time
from typing import Any

from asyncua import ua

from controller.operator.opcua import values
from controller.operator.opcua.view import View

log = logging.getLogger("phcnc.opcua")
POLL_REST_S = 2.0  # status at rest: the e-stop input, the drives, a homing's end
POLL_MOVING_S = 0.1  # homing and identify push no progress: their positions are polled
RECONNECT_S = 0.5
LINE_LIMIT = 4 << 20


class Bridge:
    def __init__(self, socket_path: str, view: View) -> None:
        self.socket_path, self.view = socket_path, view
        self.seen = values.Seen()
        self._writer: asyncio.StreamWriter | None = None
        self._next_id = 0
        self._status_ids: set[int] = set()
        self.connected = asyncio.Event()

    async def run(self, stop: asyncio.Event) -> None:
        """Serve until stop; a daemon gone (restarting) is waited for, its values kept and
        the machine shown NotAvailable meanwhile."""
        while not stop.is_set():
            try:
                await self._session(stop)
            except (OSError, ConnectionError, asyncio.IncompleteReadError, ValueError,
                    ua.UaError) as exc:
                log.warning("control socket %s: %s", self.socket_path, exc)
            self.connected.clear()
            if stop.is_set():
                return
            self.seen.status = {}
            self.seen.progress = None
            await self.view.update(self.seen)
            try:
                await asyncio.wait_for(stop.wait(), RECONNECT_S)
            except TimeoutError:
                pass

    async def _session(self, stop: asyncio.Event) -> None:
        reader, writer = await asyncio.open_unix_connection(self.socket_path, limit=LINE_LIMIT)
        self._writer = writer
        self._status_ids = set()  # a request of a session before is never answered
        poll = asyncio.create_task(self._poll(stop))
        try:
            await self._send("subscribe", topics=["state", "progress"])
            await self._send("status")
            self.connected.set()
            pending = b""
            while not stop.is_set():
                chunk = await _read_or_stop(reader, stop)
                if not chunk:
                    return
                *lines, pending = (pending + chunk).split(b"\n")
                if len(pending) > LINE_LIMIT:
                    raise ValueError("a line longer than the limit")
                for message in coalesced([json.loads(line) for line in lines if line]):
                    await self._message(message)
        finally:
            poll.cancel()
            writer.close()

    async def _send(self, cmd: str, **fields: Any) -> None:
        assert self._writer is not None
        self._next_id += 1
        if cmd == "status":
            self._status_ids.add(self._next_id)
        self._writer.write(json.dumps({"id": self._next_id, "cmd": cmd, **fields}).encode()
                           + b"\n")
        await self._writer.drain()

    async def _poll(self, stop: asyncio.Event) -> None:
        while not stop.is_set():
            moving = self.seen.status.get("state") in ("HOMING", "IDENTIFYING")
            await asyncio.sleep(POLL_MOVING_S if moving else POLL_REST_S)
            if not self._status_ids:  # one at a time
                await self._send("status")

    async def _message(self, msg: dict[str, Any]) -> None:
        if "ok" in msg:
            if msg.get("id") in self._status_ids:
                self._status_ids.discard(msg["id"])
                if msg.get("ok"):
                    await self._status(msg)
            return
        event = msg.get("event")
        if event == "progress":
            if self.seen.job() is not None:
                self.seen.progress = msg
                await self.view.update(self.seen)
        elif event == "state":
            before = dict(self.seen.status)
            self.seen.status = {**before, "state": msg.get("state"), "fault": msg.get("fault")}
            await self.view.update(self.seen)  # at once; the status fills in the rest
            raised = values.message_for(before, self.seen.status)
            if raised is not None:
                await self.view.message(*raised)
            if not self._status_ids:
                await self._send("status")

    async def _status(self, reply: dict[str, Any]) -> None:
        before = self.seen.status
        status = {k: v for k, v in reply.items() if k not in ("id", "ok")}
        self.seen.status = status
        job = status.get("job")
        if job is None:
            self.seen.progress = None
        elif status.get("state") == "RUNNING" and job not in self.seen.job_started_s:
            self.seen.job_started_s = {job: time.time()}
        await self.view.update(self.seen)
        warning = values.warning_for(before, status)
        if warning is not None:
            await self.view.message(*warning)


def coalesced(messages: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """What arrived at once, in order, but of the progress events only the last: a server
    that fell behind (a loaded PC, many clients) catches up at once instead of replaying
    every report late, and the values it writes are the newest."""
    last = max((i for i, m in enumerate(messages) if m.get("event") == "progress"),
               default=-1)
    return [m for i, m in enumerate(messages) if m.get("event") != "progress" or i == last]


async def _read_or_stop(reader: asyncio.StreamReader, stop: asyncio.Event) -> bytes:
    read = asyncio.ensure_future(reader.read(1 << 16))
    stopped = asyncio.ensure_future(stop.wait())
    done, _ = await asyncio.wait({read, stopped}, return_when=asyncio.FIRST_COMPLETED)
    stopped.cancel()
    if read in done:
        return read.result()
    read.cancel()
    return b""
