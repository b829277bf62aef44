"""The hard limit switches during a job: a switch that opens stops it; a switch already open when
it started (the machine stopped on it) stops it only if the axis goes further toward it, so
that a jog or a program can move the axis off the switch."""

from __future__ import annotations

import numpy as np

from drivers.base import Drive
from drivers.io_peer import switch_side

TOWARD_MM = 1e-6  # further toward the open switch than this: stop (rounding is not motion)


class LimitWatch:
    def __init__(self, drive: Drive, axis_names: tuple[str, ...], start_mm: np.ndarray) -> None:
        self.drive, self.axis_names = drive, axis_names
        self.start_mm = start_mm.copy()
        self.open_at_start = drive.limit_input()

    def tripped(self, commanded_mm: np.ndarray) -> str | None:
        """The switch that stops the job now (commanded_mm: the last position sent), or None."""
        name = self.drive.limit_input()
        if name is None or name != self.open_at_start:
            return name
        side = switch_side(name, self.axis_names)
        if side is None:  # no side to move off from: it stops as any open switch
            return name
        axis, direction = side
        toward_mm = (commanded_mm[axis] - self.start_mm[axis]) * direction
        return name if toward_mm > TOWARD_MM else None

    def refuses(self, rows_mm: np.ndarray) -> str | None:
        """Before the first frame: why these first rows may not go (None: they may)."""
        name = self.open_at_start
        side = None if name is None else switch_side(name, self.axis_names)
        if side is None:
            return None
        axis, direction = side
        if float(np.max((rows_mm[:, axis] - self.start_mm[axis]) * direction)) > TOWARD_MM:
            return (f"hard limit: {name} tripped; the job would move "
                    f"{self.axis_names[axis].upper()} further onto it")
        return None
