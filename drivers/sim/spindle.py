"""A simulated spindle's at-speed input: true spindle_spinup_s after each start or speed change."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from controller.blocks import OutputChange
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
    """At speed once the spindle has run spinup_s since it was last started, reversed or
    given another speed; never while off. now_s: the card's clock (wall or virtual)."""

    def __init__(self, spinup_s: float, now_s: Callable[[], float]) -> None:
        self.spinup_s, self.now_s = spinup_s, now_s
        self.since_s = 0.0

    def changed(self, changes: Sequence[OutputChange]) -> None:
        """Outputs that changed a value: a spindle start or speed change restarts the ramp."""
        if any(change.name in ("spindle", "spindle_rpm") for change in changes):
            self.since_s = self.now_s()

    def at_speed(self, on: bool) -> bool:
        """The input; on: the spindle is commanded on (the drive's outputs say)."""
        return on and self.now_s() - self.since_s >= self.spinup_s
