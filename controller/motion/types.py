"""Inputs and outputs of the motion controller: settings, progress reports, the final result."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace
from typing import Any

from controller.config import MachineConfig


class Outcome(enum.Enum):
    DONE = "done"
    FAULT = "fault"
    ABORTED = "aborted"


class MotionState(enum.Enum):
    WAITING = "waiting"  # priming: no frame sent yet
    RUNNING = "running"
    STOPPING = "stopping"  # controlled stop queued (fault, abort, starved reference)
    SETTLING = "settling"  # all frames executed, waiting for the servo to settle
    PAUSED = "paused"  # at rest at a program pause (M0), waiting for the operator to resume
    HELD = "held"  # at rest on the path after a feed hold, waiting for the operator to resume
    FINISHED = "finished"


@dataclass(frozen=True)
class MotionSettings:
    cycle_frames: int = 2  # motion-loop period in card frames
    low_water_ms: float = 20.0
    high_water_ms: float = 100.0
    holdback_ms: float = 60.0  # reference kept back so that a stop can follow the path
    block_ms: float = 64.0  # virtual time: a cycle clocks and refills this much (motion/blocks.py)
    refill_ms: float = 16.0  # real time: the card is refilled once it has this much room
    settle_s: float = 0.3
    progress_every_s: float = 0.1
    in_position_mm: float = 0.002  # the motion time ends once the tool is this close to the end

    @classmethod
    def from_config(cls, config: MachineConfig, **overrides: Any) -> MotionSettings:
        ip = config.interpolator
        # Enough path for a quintic stop from the fastest feed: 15 V / (8 A), plus margin.
        stop_ms = 1e3 * 15.0 * max(ip.max_feed_mm_s, ip.rapid_feed_mm_s) / (8 * ip.max_accel_mm_s2)
        base = cls(low_water_ms=config.runtime.card_fifo_low_water_ms,
                   high_water_ms=config.runtime.card_fifo_high_water_ms,
                   in_position_mm=config.runtime.in_position_tolerance_mm,
                   holdback_ms=stop_ms + 10.0)
        return replace(base, **overrides)


@dataclass(frozen=True)
class MotionProgress:
    state: MotionState
    line: int
    feed_mm_s: float
    ferror_um: float
    fifo_ms: float
    elapsed_s: float
    executed_s: float
    planned_s: float | None  # known once the generator has finished
    override_pct: float = 100.0
    position_mm: tuple[float, ...] = ()  # encoder position, machine coordinates
    work_origin_mm: tuple[float, ...] = ()  # the work offsets the job started with (G5x + G92)

    @property
    def work_position_mm(self) -> tuple[float, ...]:
        """Machine position less the starting work origin (a program's own G10/G92 mid-run
        are not followed here)."""
        origin = self.work_origin_mm or (0.0,) * len(self.position_mm)
        return tuple(p - o for p, o in zip(self.position_mm, origin, strict=False))


@dataclass(frozen=True)
class MotionResult:
    outcome: Outcome
    message: str
    line: int
    motion_time_s: float
    planned_time_s: float
    contour_error_um: dict[str, float]
    following_error_um_max: float
    underruns: int
    late_cycles: int
    min_fifo_ms: float
    commanded_counts: dict[str, int]
    executed_counts: dict[str, int]
    final_position_mm: dict[str, float]
    position_known: bool
    time_to_first_motion_s: float | None
    extra: dict[str, Any] = field(default_factory=dict)
    settling_time_s: float = 0.0  # after motion_time_s: in position until the last frame ran
    # Measured minus modelled position (controller/motion/model_watch.py): max, rms (normal to
    # the path), samples, axes; and the warning where the model no longer holds.
    model_residual_um: dict[str, Any] = field(default_factory=dict)
    model_warning: str | None = None
