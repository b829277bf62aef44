"""The motion loop's machine outputs: each output mark's changes set on the drive when the
machine stands at the mark, an event per change, and the safe state when a job stops."""

from __future__ import annotations

from controller.blocks import OutputChange
from controller.errors import CncError
from controller.motion.events import JobEvents
from drivers.base import Drive


class OutputRunner:
    """Sets outputs through the drive (which keeps their state and drives its hardware)."""

    def __init__(self, drive: Drive, events: JobEvents) -> None:
        self.drive, self.events = drive, events

    def at_mark(self, changes: tuple[OutputChange, ...] | None, t_s: float,
                line: int) -> str | None:
        """Set one mark's changes; a message when they could not be (then: a fault)."""
        if changes is None:
            return f"the output changes of line {line} did not reach the motion process"
        try:
            changed = self.drive.set_outputs(changes)
        except CncError as exc:
            return f"line {line}: outputs could not be set: {exc}"
        self._report(changed, t_s, line)
        return None

    def to_safe(self, t_s: float, line: int) -> str | None:
        """Every output to its safe state (abort, e-stop, fault); a message if it failed."""
        try:
            changed = self.drive.safe_outputs()
        except CncError as exc:
            return f"the outputs could not be set to their safe state: {exc}"
        self._report(changed, t_s, line, safe=True)
        return None

    def report(self, changes: list[OutputChange], t_s: float, line: int) -> None:
        """Changes the drive made itself (M62's, as it clocked their frame)."""
        self._report(changes, t_s, line)

    def _report(self, changed: list[OutputChange], t_s: float, line: int,
                safe: bool = False) -> None:
        for change in changed:
            extra = {"safe": True} if safe else {}
            self.events.emit("output", t_s, line, name=change.name, value=change.value, **extra)
