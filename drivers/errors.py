"""Drive-side exceptions: one DriveError subclass per latched card condition, and homing."""

from __future__ import annotations

from controller.errors import DriveError


class UnderrunError(DriveError):
    """The card's frame FIFO ran empty mid-program; the card stopped and latched UNDERRUN."""


class DriveFaultError(DriveError):
    """An axis amplifier reported a fault (e.g. 0x2310 over-current); the card stopped."""


class LostCommunicationError(DriveError):
    """The card stopped answering the host."""


class DriveUnavailableError(DriveError):
    """The drive could not be built or opened (bad option, no device, peer silent at bring-up):
    nothing has moved."""


class DriveBusyError(DriveUnavailableError):
    """Another controller process holds the drive's port or bus (drivers/port_lock.py)."""


class BadFrameError(DriveError):
    """The host sent a frame the card cannot execute (too many pulses, FIFO overflow, shape)."""


class HomingError(DriveError):
    """A homing sequence was refused or failed: names the axis (`axis`, None when the refusal
    concerns the whole drive) and why (no homing configured, switch not found, time-out, drive
    fault during homing, frames streaming)."""

    def __init__(self, message: str, axis: str | None = None) -> None:
        self.axis = axis
        super().__init__(message)
