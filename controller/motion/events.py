"""A job's event stream: one dict per thing that happened at a point of the program (an output
changed; tool changes and probe results are further kinds), with its motion time and line,
built by controller/io_events.py as every event line is."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from controller.io_events import io_event

EventFn = Callable[[dict[str, Any]], None]
MAX_KEPT = 10_000  # events kept for the result; a longer job's earlier ones were reported live


class JobEvents:
    """emit(kind, t_s, line, **what) is the one call that adds an event of any kind: it is kept
    (the job's result) and handed to on_event (`cncctl run --json`, cncd's job log) at once."""

    def __init__(self, on_event: EventFn | None = None) -> None:
        self.on_event = on_event
        self.kept: list[dict[str, Any]] = []
        self.count = 0

    def emit(self, kind: str, t_s: float, line: int, **what: Any) -> dict[str, Any]:
        event = io_event(kind, t_s, line, **what)  # the one shape of every event line
        self.count += 1
        if len(self.kept) < MAX_KEPT:
            self.kept.append(event)
        if self.on_event is not None:
            self.on_event(event)
        return event
