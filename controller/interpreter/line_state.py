"""The interpreter's state where a program is started from line N (run from line)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from controller.blocks import PathControl, Point3
from controller.offsets import OffsetTable, describe, work_origin


@dataclass(frozen=True)
class LineState:
    """Machine position and modal state just before source line `line` is executed, as the
    whole program read from its first line would have them."""

    line: int
    position_mm: Point3  # machine coordinates
    offsets: OffsetTable  # the table in force (active system, origins, G92)
    feed_mm_s: float  # modal F (0 when none was programmed)
    absolute: bool  # G90 (False: G91)
    inch: bool  # G20 (False: G21)
    motion: str | None  # modal motion code (G0, G1, G2, G3), None after G80 or a NURBS block
    path_control: PathControl  # G61 / G61.1 / G64 with its tolerances
    spindle: str  # M3, M4 or M5
    spindle_rpm: float | None  # modal S (None under G96, where S is a surface speed)
    coolant: tuple[str, ...]  # M7 and/or M8 when on, () after M9
    tool: int  # last T word

    @property
    def distance_mode(self) -> str:
        return "G90" if self.absolute else "G91"

    @property
    def system(self) -> str:
        """G54 .. G59."""
        return self.offsets.active_name

    @property
    def program_position_mm(self) -> Point3:
        """The position in the active work frame (mm): what the program reads there."""
        o = work_origin(self.offsets)
        p = self.position_mm
        return p[0] - o[0], p[1] - o[1], p[2] - o[2]

    def summary(self) -> dict[str, Any]:
        """JSON-able form (for the operator's views)."""
        return {
            "line": self.line,
            "position_mm": list(self.position_mm),
            "program_position_mm": list(self.program_position_mm),
            "feed_mm_s": self.feed_mm_s,
            "distance_mode": self.distance_mode,
            "units": "G20" if self.inch else "G21",
            "motion": self.motion,
            "path_control": {"mode": str(self.path_control.mode),
                             "tolerance_mm": self.path_control.tolerance_mm,
                             "naive_cam_tolerance_mm":
                                 self.path_control.naive_cam_tolerance_mm},
            "spindle": self.spindle,
            "spindle_rpm": self.spindle_rpm,
            "coolant": list(self.coolant),
            "tool": self.tool,
            "offsets": describe(self.offsets),
        }
