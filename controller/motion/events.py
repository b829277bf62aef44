"""A job's event stream: one dict per thing that happened at a point of the program (an output
changed; tool changes and probe results are further kinds), with its motion time and line."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

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
        event = {"event": kind, "t_s": round(float(t_s), 6), "line": int(line), **what}
        self.count += 1
        if len(self.kept) < MAX_KEPT:
            self.kept.append(event)
        if self.on_event is not None:
            self.on_event(event)
        return event
