"""A drive that reports the spindle's at-speed input (io.spindle.at_speed_input)."""

from __future__ import annotations

from abc import ABC, abstractmethod


class AtSpeedInput(ABC):
    """Mixed into a Drive with an at-speed input: the sim card, the serial card, CANopen.
    at_speed_input_name says which input it is, for messages."""

    at_speed_input_name: str = "the drive's at-speed input"

    @abstractmethod
    def at_speed_input(self) -> bool:
        """True while the spindle is at the commanded speed (the input, as read now)."""
