"""A run's tool changes as the machine reaches them: the operator's prompt and `--json` events."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from controller.io_events import io_event
from controller.motion.types import MotionProgress, MotionState


class ToolChanges:
    """The interpreter's tool-change events (t_s None) by line; `at_pause` times and emits the
    one of the line the machine paused at (once), through `emit(event_dict)`."""

    def __init__(self, events: list[dict[str, Any]],
                 emit: Callable[[dict[str, Any]], None]) -> None:
        self.by_line = {e["line"]: e for e in events if e.get("event") == "tool"}
        self.emit = emit
        self.done: set[int] = set()

    def prompt(self, line: int) -> str | None:
        """What the operator is asked at a pause on `line`; None: not a tool change."""
        event = self.by_line.get(line)
        if event is None:
            return None
        return (f"tool change at line {line} (M6): put in T{event['tool']} (length "
                f"{event['table_length_mm']:g} mm in the table)")

    def at_pause(self, p: MotionProgress) -> None:
        if p.state is not MotionState.PAUSED or p.line in self.done or p.line not in self.by_line:
            return
        self.done.add(p.line)
        what = {k: v for k, v in self.by_line[p.line].items() if k not in ("event", "t_s", "line")}
        self.emit(io_event("tool", p.elapsed_s, p.line, **what))
