"""The simulated drives' touch probe (CiA 402 60B8h-60BBh): one probe input wired to every
drive, in contact while the table is inside the simulated work (probe_workpiece_mm, as the sim
card's); each armed drive latches its own position at the edge, exact along the cycle's step."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from controller.probe import Workpiece, trip_point
from drivers.canopen import cia402 as c
from drivers.io_peer import workpiece_option

PROBE_OPTIONS = frozenset({"probe_workpiece_mm"})


class SimTouchProbe402:
    """Shared by the drives of one bus; each reads and writes with its axis index."""

    def __init__(self, options: dict[str, Any], axes: tuple[str, ...]) -> None:
        self.work: Workpiece | None = workpiece_option(
            options.get("probe_workpiece_mm"), "simulated drive option"
        )
        self.axes = axes
        self.function = [0] * len(axes)  # 60B8 as written
        self.status = [0] * len(axes)  # 60B9
        self.latched = [[0, 0] for _ in axes]  # 60BA, 60BB: counts
        self.contact = False
        self.last_xyz: list[float] | None = None

    def write(self, axis: int, index: int, value: int) -> bool:
        """An SDO write of 60B8 (False: another object). Writing it re-arms: the stored
        edges are cleared, as a drive does when probe 1 is switched on again."""
        if index != c.TOUCH_PROBE_FUNCTION:
            return False
        self.function[axis] = value
        self.status[axis] = c.TPS_ENABLED if value & c.TPF_ENABLE else 0
        return True

    def read(self, axis: int, index: int) -> int | None:
        """60B8-60BB of one drive (None: another object)."""
        return {
            c.TOUCH_PROBE_FUNCTION: self.function[axis],
            c.TOUCH_PROBE_STATUS: self.status[axis],
            c.TOUCH_PROBE_POSITIVE: self.latched[axis][0],
            c.TOUCH_PROBE_NEGATIVE: self.latched[axis][1],
        }.get(index)

    def statusword_bits(self) -> int:
        return c.SW_PROBE_INPUT if self.contact else 0

    def observe(self, actual_mm: Sequence[float], counts_per_mm: Sequence[float]) -> None:
        """After a SYNC's step: the input's level now, and at an edge each armed drive's
        latch (the crossing of the work's face between the last step and this one)."""
        if self.work is None:
            return
        xyz = self._xyz(actual_mm)
        contact = self.work.contact(xyz)
        before, self.last_xyz = self.last_xyz, xyz
        if before is None or contact == self.contact:
            self.contact = contact
            return
        self.contact = contact
        at = trip_point(self.work, before, xyz, toward=contact) or xyz
        for i, name in enumerate(self.axes):
            self._latch(i, contact, at["xyz".index(name)] * counts_per_mm[i])

    def _latch(self, axis: int, positive: bool, counts: float) -> None:
        f = self.function[axis]
        wanted = c.TPF_POSITIVE_EDGE if positive else c.TPF_NEGATIVE_EDGE
        stored = c.TPS_POSITIVE_STORED if positive else c.TPS_NEGATIVE_STORED
        if not f & c.TPF_ENABLE or not f & wanted or self.status[axis] & stored:
            return  # off, the other edge, or its first event already stored
        self.latched[axis][0 if positive else 1] = int(round(counts))
        self.status[axis] |= stored

    def _xyz(self, actual_mm: Sequence[float]) -> list[float]:
        """Machine X Y Z; an axis the machine lacks is inside the work (an X-Y table probes
        in X and Y, as the sim card's)."""
        assert self.work is not None
        xyz = list(self.work.min_mm)
        for name, mm in zip(self.axes, actual_mm, strict=True):
            xyz["xyz".index(name)] = float(mm)
        return xyz
