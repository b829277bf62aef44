"""One job of the daemon: the program, where it started, its progress, and its events; and the
states the daemon's machine goes through."""

from __future__ import annotations

import enum
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from controller.motion.types import MotionProgress
from controller.runtime.probe_run import ProbeRun
from controller.runtime.processes import Runtime

Emit = Callable[[dict[str, Any]], None]
# A job's progress every 40 ms (the motion loop's own default is 0.1 s): the web panel's
# status push runs at 25 Hz from these events (docs/api.md).
PROGRESS_EVERY_S = 0.04


class State(enum.StrEnum):
    ESTOP = "ESTOP"
    IDLE = "IDLE"
    CHECKING = "CHECKING"
    RUNNING = "RUNNING"
    HOMING = "HOMING"
    IDENTIFYING = "IDENTIFYING"  # `cncctl identify` excites the axes, then fits their loops
    FAULT = "FAULT"


@dataclass
class Job:
    number: int
    name: str
    sha256: str
    text: bytes
    lines: int
    emit: Emit  # events for the connection that started it (and the state subscribers)
    runtime: Runtime | ProbeRun | None = None  # ProbeRun: a program with probes (G38)
    cancel: str | None = None  # abort or e-stop asked while checking
    start_mm: tuple[float, float, float] | None = None  # where the machine stood
    progress: MotionProgress | None = None
    holding: bool = False  # a feed hold was asked and not resumed
    optional_stop: bool = False  # M1 pauses like M0
    from_line: int | None = None  # run from this line, after an approach move
    manual_move: bool = False  # a jog: machine coordinates, no offsets
    approach_mm: tuple[float, float, float] | None = None  # where line from_line starts
    approaching: bool = False  # the approach is moving (its lines are not the program's)
    tool_changes: list[dict[str, Any]] = field(default_factory=list)  # M6s the check found
    emitted_lines: set[int] = field(default_factory=set)  # tool changes already announced
    done: threading.Event = field(default_factory=threading.Event)


def progress_event(p: MotionProgress) -> dict[str, Any]:
    return {"event": "progress", "state": p.state.value, "line": p.line,
            "feed_mm_s": round(p.feed_mm_s, 3), "ferror_um": round(p.ferror_um, 1),
            "fifo_ms": round(p.fifo_ms, 1), "elapsed_s": round(p.elapsed_s, 3),
            "executed_s": round(p.executed_s, 3), "planned_s": p.planned_s,
            "override_pct": p.override_pct, "position_mm": list(p.position_mm),
            "work_origin_mm": list(p.work_origin_mm),
            # when the motion loop reported it (CLOCK_MONOTONIC, one clock for the whole
            # machine): a client on the same PC measures its latency from the loop
            "t_mono": round(time.monotonic(), 6)}
