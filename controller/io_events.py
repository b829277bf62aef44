"""A run's events (output changes, tool changes, probe results) as the dicts `run --json` prints:
one builder for every kind, so each JSON event line has the same shape."""

from __future__ import annotations

from typing import Any

EVENT_KINDS = ("output", "tool", "probe")
T_DECIMALS = 6  # t_s to the microsecond: a sample period is a whole number of them


def io_event(kind: str, t_s: float | None, line: int, **what: Any) -> dict[str, Any]:
    """One event: `{"event": kind, "t_s": ..., "line": ..., **what}`. t_s is the run's time
    (s since its start) when the machine got there; None while only the interpreter knows it."""
    if kind not in EVENT_KINDS:
        raise ValueError(f"unknown I/O event {kind!r} (one of {', '.join(EVENT_KINDS)})")
    return {"event": kind, "t_s": None if t_s is None else round(float(t_s), T_DECIMALS),
            "line": int(line), **what}
