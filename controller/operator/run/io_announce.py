"""A run's tool changes as the machine reaches them: the operator's prompt and `--json` events."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from controller.io_events import io_event
from controller.motion.types import MotionProgress, MotionState


class ToolChanges:
    """The interpreter's tool-change events (t_s None) by line; `at_pause` times and emits the
    one of the line the machine paused at (once), through `emit(event_dict)`."""

    def __init__(self, events: list[dict[str, Any]], emit: Callable[[dict[str, Any]], None],
                 done: set[int] | None = None) -> None:
        self.by_line = {e["line"]: e for e in events if e.get("event") == "tool"}
        self.emit = emit
        self.done: set[int] = set() if done is None else done

    def prompt(self, line: int) -> str | None:
        """What the operator is asked at a pause on `line`; None: not a tool change."""
        return tool_prompt(list(self.by_line.values()), line)

    def at_pause(self, p: MotionProgress) -> None:
        if p.state is not MotionState.PAUSED or p.line in self.done or p.line not in self.by_line:
            return
        self.done.add(p.line)
        what = {k: v for k, v in self.by_line[p.line].items() if k not in ("event", "t_s", "line")}
        self.emit(io_event("tool", p.elapsed_s, p.line, **what))


def tool_change_at(events: list[dict[str, Any]], p: MotionProgress,
                   done: set[int]) -> list[dict[str, Any]]:
    """The timed tool event of the M6 the machine paused at, once per line (`done` keeps the
    lines announced); [] elsewhere."""
    out: list[dict[str, Any]] = []
    ToolChanges(events, out.append, done).at_pause(p)
    return out


def tool_prompt(events: list[dict[str, Any]], line: int) -> str | None:
    """The operator's prompt at a pause on `line` if an M6 is there (None: not a tool change)."""
    for event in events:
        if event.get("event") == "tool" and event["line"] == line:
            return (f"tool change at line {line} (M6): put in T{event['tool']} (length "
                    f"{event['table_length_mm']:g} mm in the table)")
    return None
