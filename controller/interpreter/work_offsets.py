"""Work offsets in the interpreter: G54-G59, G10 L2 / L20, G92 / G92.1 / G92.2 (LinuxCNC's
rules: G91 changes none of them; G10 L2 values are machine coordinates, G10 L20 and G92 values
are what the current position shall read)."""

from __future__ import annotations

from controller.interpreter.codes import WordError
from controller.offsets import (
    SYSTEMS,
    ZERO_MM,
    OffsetTable,
    Point3,
    ProgramOffsets,
    select,
    with_g92,
    with_system,
    work_origin,
)

_AXES = "XYZ"
AXIS_CODES = frozenset((100, 920))  # G10 and G92 take the line's axis words for themselves


class WorkOffsets:
    """The offset table in force and the work origin it gives; G54-G59, G10 and G92 change it.

    `track`, if given, is told every new table (what a caller reads after the program)."""

    def __init__(self, table: OffsetTable, track: ProgramOffsets | None, has_z: bool,
                 config_name: str) -> None:
        self.track = track
        self.has_z = has_z
        self.config_name = config_name  # named in the refusal of a Z offset without Z axis
        self.table = table
        self.origin: Point3 | None = None  # active system + G92 + tool length; None: zero
        self.tool_mm = 0.0  # the tool length offset in force (G43), on Z
        self.set(table)

    def set(self, table: OffsetTable) -> None:
        """Put `table` in force: its origin becomes the program frame's."""
        self.table = table
        x, y, z = work_origin(table)
        origin = (x, y, z + self.tool_mm)
        self.origin = None if origin == ZERO_MM else origin
        if self.track is not None:
            self.track.table = table

    def set_tool_length(self, length_mm: float) -> None:
        """G43 / G43.1 / G49: program Z = machine Z - work origin - tool length."""
        self.tool_mm = length_mm
        self.set(self.table)

    def select_system(self, code10: int) -> None:
        """G54 .. G59 (code10 540 .. 590): the machine stays, the program frame changes."""
        n = code10 // 10 - 53
        if n != self.table.active:
            self.set(select(self.table, n))

    def apply(self, code10: int, vals: dict[str, float], pos: Point3, scale: float) -> None:
        """G10 (100), G92 (920), G92.1 (921), G92.2 (922) at machine position `pos` (mm), with
        `scale` mm per program unit."""
        if code10 == 100:
            self._g10(vals, pos, scale)
        elif code10 == 920:
            self._g92(vals, pos, scale)
        elif self.table.g92_mm != ZERO_MM:
            # G92.1 and G92.2 both clear the offset (LinuxCNC's G92.2 keeps parameters
            # 5211-5213, which phcnc does not have).
            self.set(with_g92(self.table, ZERO_MM))

    def _g10(self, vals: dict[str, float], pos: Point3, scale: float) -> None:
        if "L" not in vals:
            raise WordError("G10", "G10 needs L2 (set a work origin) or L20 (set it so that "
                                   "the current position reads X Y Z)")
        kind = vals["L"]
        if kind not in (2.0, 20.0):
            raise WordError("L", f"G10 L{kind:g} is not supported: only G10 L2 and G10 L20 "
                                 f"(work offsets); phcnc has no tool table")
        name = f"G10 L{kind:g}"
        if "R" in vals:
            raise WordError("R", f"{name} R: rotated coordinate systems are not supported")
        if "P" not in vals:
            raise WordError("G10", f"{name} needs P: the coordinate system, 1..6 for "
                                   f"G54..G59, 0 for the active one")
        p = vals["P"]
        if p != int(p) or not 0 <= p <= 9:
            raise WordError("P", f"{name} P{p:g}: P must be an integer from 0 (the active "
                                 f"system) to {SYSTEMS} (G59)")
        if p > SYSTEMS:
            raise WordError("P", f"{name} P{p:g}: coordinate systems G59.1-G59.3 are not "
                                 f"supported (P0..P{SYSTEMS} only)")
        n = int(p) or self.table.active
        old = self.table.systems_mm[n - 1]
        origin = list(old)
        g92 = self.table.g92_mm
        for i, letter in enumerate(_AXES):
            if letter in vals:
                value = vals[letter] * scale
                origin[i] = value if kind == 2.0 else pos[i] - g92[i] - self._tool(i) - value
        self._check_z(vals, origin[2], old[2])
        self.set(with_system(self.table, n, origin))

    def _g92(self, vals: dict[str, float], pos: Point3, scale: float) -> None:
        if not any(letter in vals for letter in _AXES):
            raise WordError("G92", "G92 needs at least one axis word (X, Y, Z)")
        origin = self.table.systems_mm[self.table.active - 1]
        old = self.table.g92_mm
        g92 = list(old)
        for i, letter in enumerate(_AXES):
            if letter in vals:
                g92[i] = pos[i] - origin[i] - self._tool(i) - vals[letter] * scale
        self._check_z(vals, g92[2], old[2])
        self.set(with_g92(self.table, g92))

    def _tool(self, i: int) -> float:
        return self.tool_mm if i == 2 else 0.0

    def _check_z(self, vals: dict[str, float], new: float, old: float) -> None:
        if "Z" in vals and not self.has_z and new != old:
            raise WordError("Z", f"Z offset on a machine without a Z axis "
                                 f"(config '{self.config_name}')")
