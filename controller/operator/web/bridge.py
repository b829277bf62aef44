"""The panel's view of the daemon: one connection subscribed to its state, progress and log
events, one for requests and for polling `status` while no job reports progress; the merged
status is pushed to every listener at 25 Hz or more."""

from __future__ import annotations

import asyncio
import sys
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from controller.operator.client import DaemonUnavailable
from controller.operator.web.daemon_link import DaemonLink

PUSH_PERIOD_S = 0.04  # 25 Hz: the status poll's period while no job reports progress
UNWATCHED_POLL_PERIOD_S = 1.0  # no WebSocket open: nobody sees a push (GET /api/status polls)
BUSY_POLL_PERIOD_S = 0.25  # during a job (its progress events carry position and line)
PROGRESS_FRESH_S = 0.1  # progress this recent: the job reports, polling slows down
LOG_KEPT = 200
# what the 25 Hz push carries (the last job and homing are in the job events and the log):
# about 1 kB a push, to each of 20 tablets
STATUS_KEYS = ("state", "fault", "program", "job", "line", "feed_mm_s", "ferror_um",
               "feed_override_pct", "position_mm", "work_position_mm", "drives",
               "estop_input", "homed", "offsets", "outputs")
# a job's motion states that the daemon's status reports as states of their own
_MOTION_STATES = {"paused": "PAUSED", "held": "HELD"}

Listener = Callable[[str, dict[str, Any]], None]


def work_position(position_mm: dict[str, float] | None,
                  origin_mm: dict[str, float]) -> dict[str, float] | None:
    if position_mm is None:
        return None
    return {a: round(v - origin_mm.get(a, 0.0), 6) for a, v in position_mm.items()}


class Bridge:
    """Owns the two daemon connections; listeners get ("status" | "log" | "job", message)."""

    def __init__(self, socket_path: str, axes: tuple[str, ...]) -> None:
        self.socket_path, self.axes = socket_path, axes
        self.status: dict[str, Any] = {"state": "UNKNOWN", "seq": 0}
        self.log: deque[dict[str, Any]] = deque(maxlen=LOG_KEPT)
        self.listeners: set[Listener] = set()
        self.cmd: DaemonLink | None = None
        self.sub: DaemonLink | None = None
        self._progress_s = 0.0
        self._daemon_state = "UNKNOWN"
        self._tasks: list[asyncio.Task[None]] = []
        self.watched: Callable[[], bool] = lambda: True  # is anyone subscribed to the push
        self.polled_s = 0.0
        self.wake = asyncio.Event()

    async def start(self) -> None:
        self.sub = await DaemonLink(self.socket_path, self._event).open()
        self.cmd = await DaemonLink(self.socket_path).open()
        await self.sub.request("subscribe", topics=["state", "progress", "log"])
        for event in (await self.cmd.request("log", lines=LOG_KEPT))["events"]:
            self.log.append(event)
        await self.poll()
        self._tasks.append(asyncio.create_task(self._poll_loop()))

    async def gone(self) -> None:
        """Returns when the daemon hangs up either connection (the panel then stops)."""
        assert self.sub is not None and self.cmd is not None
        waits = [asyncio.create_task(link.closed.wait()) for link in (self.sub, self.cmd)]
        await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        for w in waits:
            w.cancel()

    async def request(self, cmd: str, payload: bytes = b"", **fields: Any) -> dict[str, Any]:
        if self.cmd is None:
            raise DaemonUnavailable("not connected to the daemon")
        return await self.cmd.request(cmd, payload, **fields)

    async def poll(self) -> None:
        reply = await self.request("status")
        self.polled_s = time.monotonic()
        self._daemon_state = reply["state"]
        fresh = time.monotonic() - self._progress_s < PROGRESS_FRESH_S
        for key in STATUS_KEYS:
            if key in reply and not (fresh and key in ("line", "position_mm",
                                                        "work_position_mm", "feed_mm_s",
                                                        "ferror_um")):
                self.status[key] = reply[key]
        if not fresh:
            self.status["t_mono"] = round(time.monotonic(), 6)
            self.status["source"] = "status"
        self._push_status()

    async def _poll_loop(self) -> None:
        while True:
            fresh = time.monotonic() - self._progress_s < PROGRESS_FRESH_S
            period = (UNWATCHED_POLL_PERIOD_S if not self.watched() else
                      BUSY_POLL_PERIOD_S if fresh else PUSH_PERIOD_S)
            try:  # a WebSocket opening wakes it: its push starts at 25 Hz at once
                await asyncio.wait_for(self.wake.wait(), period)
            except TimeoutError:
                pass
            self.wake.clear()
            try:
                await self.poll()
            except DaemonUnavailable:
                if self.cmd is None or self.cmd.closed.is_set():
                    return  # the daemon hung up: gone() ends the panel
            except Exception as exc:  # noqa: BLE001  (the push must outlive any one reply)
                print(f"<4>web panel: status poll: {type(exc).__name__}: {str(exc)[:200]}",
                      file=sys.stderr, flush=True)

    def _event(self, event: dict[str, Any]) -> None:
        kind = event.get("event")
        if kind == "progress":
            self._progress(event)
        elif kind == "state":
            self._daemon_state = event["state"]
            self.status["state"], self.status["fault"] = event["state"], event.get("fault")
            self._push_status()
        elif kind == "log":
            self.log.append(event)
            self._push("log", event)

    def _progress(self, event: dict[str, Any]) -> None:
        self._progress_s = time.monotonic()
        s = self.status
        position = dict(zip(self.axes, event["position_mm"], strict=False))
        origin = dict(zip(("x", "y", "z"), event.get("work_origin_mm", ()), strict=False))
        s["position_mm"] = {a: round(v, 6) for a, v in position.items()}
        s["work_position_mm"] = work_position(s["position_mm"], origin)
        s["line"], s["feed_mm_s"] = event["line"], event["feed_mm_s"]
        s["ferror_um"], s["feed_override_pct"] = event["ferror_um"], event["override_pct"]
        s["motion"] = event["state"]
        state = self._daemon_state
        if state == "RUNNING":
            state = _MOTION_STATES.get(event["state"], state)
        s["state"] = state
        s["t_mono"], s["source"] = event.get("t_mono"), "progress"
        self._push_status()

    def _push_status(self) -> None:
        self.status["seq"] += 1
        self._push("status", self.status)

    def _push(self, kind: str, message: dict[str, Any]) -> None:
        for listener in list(self.listeners):
            listener(kind, message)

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        for link in (self.sub, self.cmd):
            if link is not None:
                await link.close()
