"""M70-M73 (LinuxCNC): save the modal state, forget it, restore it, and restore it when the
subroutine that saved it returns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from controller.blocks import PathControl, Source
from controller.interpreter.codes import WordError

SAVE, INVALIDATE, RESTORE, SAVE_AUTO = 70, 71, 72, 73
MODAL_SAVE_CODES = frozenset((SAVE, INVALIDATE, RESTORE, SAVE_AUTO))


@dataclass(frozen=True, slots=True, eq=False)
class Snapshot:
    """What M70 keeps: LinuxCNC's list, less the modes phcnc does not have (cutter
    compensation, feed mode, lathe modes, overrides): units, plane, distance modes, work
    system, tool length, canned return, spindle mode, path control, F, S, spindle, coolant."""

    scale: float
    absolute: bool
    arc_absolute: bool
    plane: int
    path_control: PathControl
    feed_mm_s: float
    system: int  # 1..6 (G54..G59)
    tool_mm: float
    tool_length_mm: float
    tool_follows_loaded: bool
    retract_to_r: bool
    css: bool
    spindle_rpm: float
    spindle_code: int
    coolant: tuple[str, ...]


class ModalContexts:
    """One saved state per call level (LinuxCNC keeps it in the call's context): M73's is
    restored when that level's subroutine returns, and any is dropped then."""

    def __init__(self, state: Any) -> None:  # the InterpState (it imports this module)
        self.state = state
        self.saved: dict[int, tuple[Snapshot, bool]] = {}  # call level -> (state, auto)
        self.return_line = 0  # the line of the endsub/return being run, for its blocks

    def run(self, m: int, lineno: int) -> None:
        level = self.state.params.depth
        if m in (SAVE, SAVE_AUTO):
            self.saved[level] = (self._snapshot(), m == SAVE_AUTO)
        elif m == INVALIDATE:
            self.saved.pop(level, None)
        elif level not in self.saved:
            raise WordError("M72", "M72: no state saved by M70 or M73 at this call level")
        else:
            self._restore(self.saved[level][0], lineno)

    def returned(self, level: int) -> None:
        """A subroutine at call level `level` returns: restore its M73 state, forget any."""
        entry = self.saved.pop(level, None)
        if entry is not None and entry[1]:
            self._restore(entry[0], self.return_line)

    def _snapshot(self) -> Snapshot:
        s = self.state
        m = s.modal
        return Snapshot(
            m.scale,
            m.absolute,
            m.arc_absolute,
            m.plane,
            m.path_control,
            m.feed_mm_s,
            s.offsets.table.active,
            s.offsets.tool_mm,
            s.tools.length_mm,
            s.tools.follows_loaded,
            s.cycles.retract_to_r,
            s.css,
            s.spindle_rpm,
            s.spindle_code,
            s.coolant,
        )

    def _restore(self, snap: Snapshot, lineno: int) -> None:
        s = self.state
        m = s.modal
        m.scale, m.absolute, m.arc_absolute = snap.scale, snap.absolute, snap.arc_absolute
        m.plane, m.path_control, m.feed_mm_s = snap.plane, snap.path_control, snap.feed_mm_s
        s.offsets.select_system(530 + 10 * snap.system)
        s.tools.length_mm, s.tools.follows_loaded = snap.tool_length_mm, snap.tool_follows_loaded
        s.offsets.set_tool_length(snap.tool_mm)
        s.cycles.retract_to_r, s.css = snap.retract_to_r, snap.css
        self._restore_outputs(snap, lineno)

    def _restore_outputs(self, snap: Snapshot, lineno: int) -> None:
        """The spindle and coolant as saved: one OutputBlock if they changed."""
        s = self.state
        coolant = snap.coolant
        ms = [snap.spindle_code] + (
            [9, *(int(c[1:]) for c in coolant)] if coolant != s.coolant else []
        )
        s.spindle_code, s.spindle_on = snap.spindle_code, snap.spindle_code != 5
        s.spindle_rpm, s.coolant = snap.spindle_rpm, coolant
        rpm = None if s.css else s.spindle_rpm
        block = s.outputs.line_block(
            ms, {"S": s.spindle_rpm}, rpm, s.modal.pos, Source(s.path, lineno, lineno)
        )
        if block is not None:
            s.out.append(block)
