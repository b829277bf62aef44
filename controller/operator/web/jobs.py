"""Jobs the panel starts: a library program, an MDI job, the job queue the operator starts job
by job, and continuous jogs held by a lease. Each job is a `run` on a connection of its own
that follows it, so its check errors and its end come back to the panel."""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Callable
from typing import Any

from controller.operator.client import DaemonError
from controller.operator.web import mdi
from controller.operator.web.bridge import Bridge
from controller.operator.web.daemon_link import DaemonLink
from controller.operator.web.library import Library

FINAL_EVENTS = ("rejected", "done", "fault", "aborted")
MAX_QUEUE = 100
JOG_LEASE_S = 0.5  # a continuous jog not renewed this long is stopped (the page went away)
MDI_SETTLE_S = 2.0  # an MDI line waits this long at most for the last one's modes
JOG_TIMEOUT_S = 60.0  # the daemon's own time-out: a jog ends even if this process dies


class Jobs:
    """Starts jobs and keeps the queue; every event of a followed job goes to `notify`."""

    def __init__(self, bridge: Bridge, library: Library, session: mdi.MdiSession,
                 notify: Callable[[str, dict[str, Any]], None]) -> None:
        self.bridge, self.library, self.session, self.notify = bridge, library, session, notify
        self.queue: list[dict[str, Any]] = []
        self._ids = itertools.count(1)
        self.last_job: dict[str, Any] | None = None
        self._followers: set[asyncio.Task[None]] = set()
        self.jog_job: int | None = None
        self.jog_owner: object | None = None
        self.jog_until_s = 0.0
        self._jog_lock = asyncio.Lock()
        self._lease_task: asyncio.Task[None] | None = None
        self._mdi_task: asyncio.Task[None] | None = None  # following the last MDI job

    async def run(self, name: str, text: bytes, mdi_lines: list[str] | None = None,
                  entry: dict[str, Any] | None = None) -> dict[str, Any]:
        """Send a program as a job through the socket's `run` (the daemon checks it whole
        before any motion, and refuses it as it would refuse cncctl's)."""
        link = await DaemonLink(self.bridge.socket_path).open()
        events: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        link.on_event = events.put_nowait
        try:
            reply = await link.request("run", text, name=name, program_bytes=len(text),
                                       follow=True)
        except BaseException:
            await link.close()
            raise
        job = {"job": reply["job"], "name": name, "state": "CHECKING", "message": None}
        self.last_job = job
        task = asyncio.create_task(self._follow(link, events, job, mdi_lines, entry))
        if mdi_lines is not None:
            self._mdi_task = task
        self._followers.add(task)
        task.add_done_callback(self._followers.discard)
        return job

    async def _follow(self, link: DaemonLink, events: asyncio.Queue[dict[str, Any]],
                      job: dict[str, Any], mdi_lines: list[str] | None,
                      entry: dict[str, Any] | None) -> None:
        try:
            while True:
                getter = asyncio.create_task(events.get())
                closed = asyncio.create_task(link.closed.wait())
                done, _ = await asyncio.wait({getter, closed},
                                             return_when=asyncio.FIRST_COMPLETED)
                closed.cancel()
                if getter not in done:
                    getter.cancel()
                    job["state"], job["message"] = "lost", "the daemon closed the connection"
                    break
                event = getter.result()
                kind = event.get("event")
                if kind == "start":
                    job["state"] = "RUNNING"
                if kind in FINAL_EVENTS:
                    job["state"], job["result"] = kind, event
                    message = event.get("message") or None
                    job["message"] = mdi.user_message(message) if mdi_lines and message \
                        else message
                    if kind == "done" and mdi_lines is not None:
                        await asyncio.to_thread(self.session.finished, mdi_lines)
                    break
                if kind != "progress":  # progress reaches the panel through the status push
                    self.notify("job", {**job, "event": event})
        finally:
            await link.close()
        if entry is not None:
            entry["state"], entry["message"] = job["state"], job["message"]
        self.notify("job", {**job, "final": True})  # with the daemon's final event (result)
        self.notify("queue", {"queue": self.queue})

    # -- MDI ---------------------------------------------------------------------------------
    async def mdi(self, text: object) -> dict[str, Any]:
        lines = mdi.check_text(text)
        last = self._mdi_task
        if last is not None and not last.done():
            # The daemon says IDLE just before the job's final event, whose modes the next
            # line needs; a job still running after this is refused `busy` by the daemon.
            await asyncio.wait({last}, timeout=MDI_SETTLE_S)
        return await self.run(mdi.JOB_NAME, self.session.job_text(lines), mdi_lines=lines)

    # -- the queue ---------------------------------------------------------------------------
    def enqueue(self, name: str) -> dict[str, Any]:
        self.library.read(name)  # it exists now
        if len(self.queue) >= MAX_QUEUE:
            raise DaemonError("full", f"the queue holds at most {MAX_QUEUE} jobs")
        entry = {"id": next(self._ids), "name": name, "state": "queued", "message": None}
        self.queue.append(entry)
        return entry

    def remove(self, entry_id: int) -> None:
        entry = self._entry(entry_id)
        if entry["state"] in ("CHECKING", "RUNNING"):
            raise DaemonError("busy", "that job is running: abort it first")
        self.queue.remove(entry)

    def _entry(self, entry_id: int) -> dict[str, Any]:
        for entry in self.queue:
            if entry["id"] == entry_id:
                return entry
        raise DaemonError("not-found", "no such queue entry")

    async def start_next(self) -> dict[str, Any]:
        """The first queued job, started; the operator starts each one (never automatic)."""
        entry = next((e for e in self.queue if e["state"] == "queued"), None)
        if entry is None:
            raise DaemonError("empty", "no queued job")
        text = self.library.read(entry["name"])
        job = await self.run(entry["name"], text, entry=entry)
        entry["state"], entry["job"] = "CHECKING", job["job"]
        return {"entry": entry, **job}

    def clear_finished(self) -> None:
        self.queue = [e for e in self.queue if e["state"] in ("queued", "CHECKING", "RUNNING")]

    # -- jogs ------------------------------------------------------------------------------
    async def jog(self, owner: object, fields: dict[str, Any]) -> dict[str, Any]:
        """An incremental jog, or a continuous one (direction) held by owner's lease."""
        async with self._jog_lock:
            continuous = "direction" in fields
            if continuous:
                fields = {**fields, "timeout_s": JOG_TIMEOUT_S}
            reply = await self.bridge.request("jog", **fields)
            if continuous:
                self.jog_job, self.jog_owner = reply["job"], owner
                self.jog_until_s = time.monotonic() + JOG_LEASE_S
                if self._lease_task is None or self._lease_task.done():
                    self._lease_task = asyncio.create_task(self._watch_lease())
            return {k: reply[k] for k in ("job", "state", "message") if k in reply}

    def renew(self, owner: object) -> bool:
        if self.jog_job is None or owner is not self.jog_owner:
            return False
        self.jog_until_s = time.monotonic() + JOG_LEASE_S
        return True

    async def jog_stop(self, owner: object | None = None, why: str = "released") -> bool:
        """Stop the continuous jog (of owner, if given): the button released, the page closed,
        the connection dropped or the lease ran out. The abort goes only to that jog's job."""
        async with self._jog_lock:
            job = self.jog_job
            if job is None or (owner is not None and owner is not self.jog_owner):
                return False
            self.jog_job = self.jog_owner = None
            try:  # the daemon's word, not the last push: the jog may just have started
                current = (await self.bridge.request("status")).get("job")
            except DaemonError:
                current = job
            if current == job:
                try:
                    await self.bridge.request("abort")
                except DaemonError:
                    pass  # it ended already (not-running)
            self.notify("jog", {"stopped": job, "why": why})
            return True

    async def _watch_lease(self) -> None:
        while self.jog_job is not None:
            await asyncio.sleep(0.05)
            if self.jog_job is not None and time.monotonic() > self.jog_until_s:
                await self.jog_stop(why="lease expired")

    async def close(self) -> None:
        await self.jog_stop(why="panel stopping")
        for task in list(self._followers):
            task.cancel()
