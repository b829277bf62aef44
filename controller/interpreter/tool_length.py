"""Tools in the interpreter: T, M6 (a manual tool change), G43 H, G43.1 Z and G49 (H0) on Z.

LinuxCNC's model: T selects a tool, M6 loads it; G43 Hn puts tool n's length in force (H
missing: the loaded tool), G43.1 Z a length given in the program, G49 none. The length offsets
Z like a work offset does (program Z = machine Z - work origin - length), so the travel check
of the blocks checks it too. While G43 follows the loaded tool, an M6 puts the new tool's
length in force. The table is the config's (`tools.table`); None means no table is in force:
T words are then unchecked and every length is zero, as before tools existed.
"""

from __future__ import annotations

from collections.abc import Callable

from controller.blocks import AuxBlock, LineBlock, NcBlock, PathControl, Source, StopBlock, StopKind
from controller.config import MachineConfig
from controller.interpreter.codes import WordError
from controller.interpreter.modal import Modal
from controller.interpreter.work_offsets import WorkOffsets
from controller.io_events import io_event
from controller.tools import ToolTable


class ToolState:
    """The selected and loaded tool and the length in force; M6's blocks go to `out`."""

    def __init__(self, config: MachineConfig, modal: Modal, offsets: WorkOffsets, path: str,
                 out: list[NcBlock]) -> None:
        self.table: ToolTable | None = config.tools.table
        self.change_mm = config.tools.change_position_mm
        self.has_z = config.has_axis("z")
        self.config_name = config.name
        self.rapid_mm_s = config.interpolator.rapid_feed_mm_s
        self.modal, self.offsets, self.path, self.out = modal, offsets, path, out
        self.selected = 0  # last T word
        self.loaded = 0  # the tool in the spindle (after M6)
        self.follows_loaded = False  # G43 without H, or H = the loaded tool: M6 changes it
        self.length_mm = 0.0  # the tool length offset in force
        self.events: list[dict[str, object]] = []  # tool changes, for the run's event stream
        # (lineno, word, message): a word accepted beyond LinuxCNC; InterpState's warn_word
        self.warn_word: Callable[[int, str, str], None] = lambda lineno, word, message: None
        self._g49_h0_said = False

    def select(self, value: float) -> None:
        """A T word: the tool must be in the table (when one is in force)."""
        self.selected = self._tool_number(value, "T", "tool number")

    def _tool_number(self, value: float, word: str, what: str) -> int:
        """value as a tool number: a non-negative integer, in the table when one is in force."""
        if value < 0 or value != int(value):
            raise WordError(word, f"{what} must be a non-negative integer")
        number = int(value)
        if self.table is not None and number and self.table.get(number) is None:
            raise WordError(word, f"T{number} is not in the tool table (`cncctl tool list`)")
        return number

    def set_loaded(self, value: float | None) -> None:
        """M61 Q: the tool in the spindle is Q, without a change (LinuxCNC); like M6, a G43
        that follows the loaded tool puts its length in force."""
        if value is None:
            raise WordError("M61", "M61 needs Q (the tool number)")
        number = self._tool_number(value, "Q", "M61 Q")
        self.loaded = number
        if self.follows_loaded:
            self._put_length(self._length_of(number, "Q"), "M61")

    def change(self, lineno: int) -> None:
        """M6 (the spindle already stopped, an OutputBlock): go to the change position, pause
        for the operator, then the new tool is loaded."""
        src = Source(self.path, lineno, lineno)
        self.out.append(AuxBlock("M6", None, self.selected, src))
        if self.change_mm is not None:
            self._go_to_change_position(src)
        self.out.append(StopBlock(StopKind.PAUSE, self.modal.pos, src))
        self.loaded = self.selected
        if self.follows_loaded:
            self._put_length(self._length_of(self.loaded, "M6"), "M6")
        self.events.append(io_event("tool", None, lineno, tool=self.loaded,
                                    table_length_mm=self._length_of(self.loaded, "T"),
                                    length_mm=self.length_mm,
                                    position_mm=[round(v, 4) for v in self.modal.pos]))

    def _go_to_change_position(self, src: Source) -> None:
        """Rapids in machine coordinates: Z up first (clear of the work), then X Y."""
        x, y, z = self.modal.pos
        target = (*self.change_mm, z)[:3] if not self.has_z else self.change_mm
        tx, ty, tz = float(target[0]), float(target[1]), float(target[2])
        for end in ((x, y, tz), (tx, ty, tz)):
            if end != self.modal.pos:
                self.out.append(LineBlock(self.modal.pos, end, self.rapid_mm_s, True,
                                          PathControl(), src))
                self.modal.pos = end

    def g43(self, vals: dict[str, float]) -> None:
        """G43 [H]: the length of tool H (the loaded one without H) in force."""
        if "H" in vals:
            h = vals["H"]
            if h < 0 or h != int(h):
                raise WordError("H", "H must be a non-negative tool number")
            number = int(h)
        else:
            number = self.loaded
        self.follows_loaded = number == self.loaded
        self._put_length(self._length_of(number, "H"), "H" if "H" in vals else "G43")

    def g43_1(self, vals: dict[str, float]) -> None:
        """G43.1 Z: the length given (program units), not from the table."""
        if "Z" not in vals:
            raise WordError("G43.1", "G43.1 needs Z: the tool length")
        self.follows_loaded = False
        self._put_length(vals["Z"] * self.modal.scale, "Z")

    def g49(self, h: float | None = None, lineno: int = 0) -> None:
        """G49: no length in force. `G49 H0` (FreeCAD's Centroid post) is G49: H0 names no
        tool in Fanuc's and Centroid's G43/G49; LinuxCNC refuses H with G49, so it warns."""
        if h is not None:
            self._g49_h(h, lineno)
        self.follows_loaded = False
        self._put_length(0.0, "G49")

    def _g49_h(self, h: float, lineno: int) -> None:
        if h != 0:
            raise WordError("H", f"H{h:g} with G49, which puts no tool length in force (only "
                                 "H0, no tool, is read with it)")
        if not self._g49_h0_said:
            self._g49_h0_said = True
            self.warn_word(lineno, "H0", "G49 H0 read as G49: H0 is no tool (Fanuc's and "
                                         "Centroid's rule; LinuxCNC refuses H with G49)")

    def _length_of(self, number: int, word: str) -> float:
        if self.table is None or number == 0:
            return 0.0
        try:
            return self.table.length_mm(number)
        except KeyError:
            raise WordError(word, f"T{number} is not in the tool table (`cncctl tool "
                                  "list`)") from None

    def _put_length(self, length_mm: float, word: str) -> None:
        if length_mm != 0.0 and not self.has_z:
            raise WordError(word, f"tool length {length_mm:g} mm on a machine without a Z "
                                  f"axis (config '{self.config_name}')")
        self.length_mm = length_mm
        self.offsets.set_tool_length(length_mm)
