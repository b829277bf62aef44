"""A simulated spindle's at-speed input: true spindle_spinup_s after each start or speed change."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from controller.io_config import SpindleIo
from drivers.errors import DriveError

NEVER = "never"  # spindle_spinup_s=never: the input never comes true (a spindle that stalls)


def spinup_option(value: Any, who: str) -> float:
    """The option's seconds (0 and up; math.inf for "never"), or a DriveError naming it."""
    if value is None:
        return 0.0
    if str(value).strip().lower() == NEVER:
        return math.inf
    try:
        spinup_s = float(value)
    except (TypeError, ValueError):
        raise DriveError(
            f"{who} spindle_spinup_s: {value!r} is not a number or {NEVER!r}"
        ) from None
    if not 0.0 <= spinup_s <= 600.0:
        raise DriveError(f"{who} spindle_spinup_s: {value!r} is not in [0, 600]")
    return spinup_s


class SimSpindle:
    """At speed once the spindle has run spinup_s since the outputs last started, reversed or
    sped it (io.spindle's on bit, reverse bit, speed channel as written); never while off.
    Without an on bit the spindle is on while its speed channel is not 0. now_s: the card's
    clock (wall or virtual)."""

    def __init__(self, spindle: SpindleIo, spinup_s: float, now_s: Callable[[], float]) -> None:
        self.io, self.spinup_s, self.now_s = spindle, spinup_s, now_s
        self.state: tuple[bool, bool, float] = (False, False, 0.0)  # on, reverse, rpm
        self.since_s = 0.0

    def written(self, bits: int, analog: Sequence[float]) -> None:
        """The outputs written (digital bits, analog channels): a change restarts the ramp."""
        sp = self.io
        rpm = float(analog[sp.speed_channel]) if sp.speed_channel is not None else 0.0
        on = bool(bits >> sp.on_bit & 1) if sp.on_bit is not None else rpm != 0.0
        reverse = sp.reverse_bit is not None and bool(bits >> sp.reverse_bit & 1)
        if (on, reverse, rpm) != self.state:
            self.state, self.since_s = (on, reverse, rpm), self.now_s()

    def at_speed(self) -> bool:
        """The input, as read now."""
        return self.state[0] and self.now_s() - self.since_s >= self.spinup_s
