"""The spindle's at-speed wait: at an output mark that starts the spindle (or changes its speed
while on), the machine stands there until the drive's at-speed input is true, or faults."""

from __future__ import annotations

from collections.abc import Callable

from controller.blocks import OutputChange
from controller.errors import CncError
from controller.io_config import SpindleIo
from drivers.at_speed_input import AtSpeedInput
from drivers.base import Drive


class AtSpeedWait:
    """Used only with io.spindle.at_speed_input (otherwise spin_up_s is planned rows at rest).
    now_s: the loop's clock (the pacer's elapsed time: wall or virtual)."""

    def __init__(self, spindle: SpindleIo, drive: Drive, now_s: Callable[[], float]) -> None:
        self.enabled, self.timeout_s = spindle.at_speed_input, spindle.at_speed_timeout_s
        self.drive, self.now_s = drive, now_s
        self.since_s: float | None = None  # waiting since then (None: not waiting)
        self.line = 0

    @property
    def waiting(self) -> bool:
        return self.since_s is not None

    def begin(self, changes: tuple[OutputChange, ...] | None, line: int) -> bool:
        """After a mark's changes were set: True when the machine must now wait for the input
        (a spindle start, reversal or speed change that leaves the spindle on)."""
        spindle = any(ch.name in ("spindle", "spindle_rpm") for ch in changes or ())
        if not (self.enabled and spindle and self.drive.outputs().get("spindle") != "off"):
            return False
        self.since_s, self.line = self.now_s(), line
        return True

    def poll(self) -> str | None:
        """Once a cycle while waiting: ends the wait when the input is true; a fault's message
        when the drive has no such input or the time-out has passed."""
        if not isinstance(self.drive, AtSpeedInput):
            self.since_s = None
            return (
                f"line {self.line}: io.spindle.at_speed_input is set, but the drive "
                f"{type(self.drive).__name__} has no spindle at-speed input"
            )
        try:
            at_speed = self.drive.at_speed_input()
        except CncError as exc:
            self.since_s = None
            return f"line {self.line}: the spindle's at-speed input could not be read: {exc}"
        if at_speed:
            self.since_s = None
            return None
        if self.now_s() - self.since_s < self.timeout_s:  # type: ignore[operator]
            return None
        self.since_s = None
        return (
            f"line {self.line}: spindle not at speed within {self.timeout_s:g} s "
            f"(input: {self.drive.at_speed_input_name}, io.spindle.at_speed_timeout_s)"
        )
