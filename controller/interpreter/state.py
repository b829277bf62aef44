"""Modal state of the interpreter and the execution of one line, in LinuxCNC's order."""

from __future__ import annotations

from controller.blocks import (
    DwellBlock,
    NcBlock,
    PathControl,
    PathMode,
    Source,
    StopBlock,
    StopKind,
)
from controller.config import MachineConfig
from controller.errors import NcError
from controller.interpreter.canned import CYCLES, CannedCycles
from controller.interpreter.codes import G_GROUP, M_GROUP, WordError, g_name
from controller.interpreter.homes import HOME_CODES, HomePositions
from controller.interpreter.line_state import LineState
from controller.interpreter.modal import Modal
from controller.interpreter.modal_save import MODAL_SAVE_CODES, ModalContexts
from controller.interpreter.moves import MAX_BLOCK_S, Moves
from controller.interpreter.outputs import M_LETTERS, ProgramOutputs
from controller.interpreter.params import Parameters
from controller.interpreter.polar import POLAR_LETTERS, check_polar, has_polar
from controller.interpreter.probing import PROBE_CODE10, Probing
from controller.interpreter.system_params import SystemParams
from controller.interpreter.tool_length import ToolState
from controller.interpreter.work_offsets import AXIS_CODES, WorkOffsets
from controller.offsets import OffsetTable, ProgramOffsets

MM_PER_INCH = 25.4
# A feed below this is refused (F0 stays "no feed yet"): a move planned at 1e-10 mm/min would
# take 1e13 s of samples. grbl raises such feeds to the same minimum; refusing says so.
MIN_FEED_MM_MIN = 1.0
_AXES = frozenset("XYZ")
_MOVE = _AXES | POLAR_LETTERS  # the words of an end point (@ ^: polar.py)
MAX_WARNINGS = 10
_STOPS = {0: StopKind.PAUSE, 1: StopKind.OPTIONAL_PAUSE, 2: StopKind.END, 30: StopKind.END_REWIND}
# Letters each G code may use (besides F S T, allowed everywhere).
_USES: dict[int, frozenset[str]] = {
    0: _MOVE, 10: _MOVE, 20: _MOVE | set("IJRP") | {"K"}, 30: _MOVE | set("IJRP") | {"K"},
    51: _MOVE | set("IJ"), 52: frozenset("XYZPL"), 62: frozenset("XYZRKPQ"), 40: frozenset("P"),
    640: frozenset("PQ"), 430: frozenset("H"), 431: frozenset("Z"), 490: frozenset("H"),
    100: _AXES | set("LPR"), 920: _AXES, 382: _MOVE, 383: _MOVE, 384: _MOVE, 385: _MOVE,
    280: _AXES, 300: _AXES,
    **{code: _MOVE | set("RLPQ") for code in CYCLES},
}
_ALWAYS = frozenset("FST")
_FAST_MOTIONS = frozenset((0, 10, 20, 30))
_LINE_LETTERS = frozenset("XYZF")
_ARC_LETTERS = frozenset("XYZFIJR")


class InterpState:
    """The execution of one line on the interpreter's state; collects blocks in `out`.

    The state is owned by parts: `modal` (position in machine mm, units, distance modes, feed,
    motion mode, path control: shared with the others), `offsets` (the work offset table and
    its origin) and `moves` (the motion words and the open NURBS block). Spindle, coolant,
    tool and the run-from-line mark are this class's own."""

    def __init__(self, path: str, config: MachineConfig,
                 start_mm: tuple[float, float, float] | None = None,
                 offsets: OffsetTable | None = None,
                 track: ProgramOffsets | None = None) -> None:
        self.path = path
        self.config = config
        self.out: list[NcBlock] = []  # Moves appends here too: cleared, never replaced
        self.modal = Modal(pos=start_mm if start_mm is not None else (0.0, 0.0, 0.0))
        self.offsets = WorkOffsets(offsets if offsets is not None else OffsetTable(), track,
                                   config.has_axis("z"), config.name)
        self.moves = Moves(self.modal, self.offsets, config, path, self.out)
        self.tools = ToolState(config, self.modal, self.offsets, path, self.out)
        self.moves.warn_word = self.tools.warn_word = self.warn_word
        if track is not None:
            self.tools.events = track.io_events  # the caller reads them after the program
        self.probing = Probing(self.modal, self.offsets, self.moves, path, self.out,
                               None if track is None else track.probes)
        self.track = track
        self.params = Parameters()
        self.params.system = SystemParams(self)
        self.contexts = ModalContexts(self)  # M70-M73
        self.params.on_return = self.contexts.returned
        self.cycles = CannedCycles(self.modal, self.moves, path)
        self.homes = HomePositions(self.modal, self.moves, self.params)
        self.spindle_rpm = 0.0
        self.spindle_on = False
        self.spindle_code = 5  # M3, M4 or M5
        self.coolant: tuple[str, ...] = ()
        self.css = False  # G96: S is a surface speed
        self.outputs = ProgramOutputs(config)  # what the program's M codes have set
        self.ended = False
        self.mark_pending: int | None = None  # run from this line once the NURBS block ends
        self.at_line: LineState | None = None  # the state where the run from line starts
        self.locate = lambda n: (path, n)  # line number -> (file, line): subroutine files

    # ---- one line ---------------------------------------------------------------------------
    def execute(self, gs: list[int], ms: list[int], vals: dict[str, float], lineno: int) -> None:
        moves = self.moves
        if moves.nurbs is not None and moves.nurbs_line(gs, ms, vals, lineno):
            if self.mark_pending is not None:
                raise self.inside_nurbs(self.mark_pending)
            return
        if self.mark_pending is not None:
            self.mark(self.mark_pending)
        if not ms and len(gs) <= 1 and self.fast(gs[0] if gs else -1, vals, lineno):
            return
        if 800 in gs and len(gs) > 1:
            gs = _drop_g80(gs)
        groups = _groups(gs, G_GROUP, g_name)
        mgroups = _groups(ms, M_GROUP, lambda m: f"M{m}")
        motion = groups.get("motion")
        nonmodal = groups.get("non-modal")
        # G10, G92, G28/G30 and G43.1 take the line's axis words for themselves
        axis_code = (nonmodal in AXIS_CODES or nonmodal in HOME_CODES
                     or groups.get("tool length") == 431)
        if axis_code and motion is not None and motion != 800:
            word = g_name(nonmodal if nonmodal in AXIS_CODES or nonmodal in HOME_CODES
                          else 431)
            raise WordError(word, f"{word} and {g_name(motion)} both use axis words: put "
                                  f"them on separate lines")
        if has_polar(vals):  # @ ^ name the end of a motion only
            check_polar(vals, groups, self.modal, axis_code)
        _check_letters(groups, vals,
                       motion if motion is not None or axis_code else self.modal.motion, ms)
        self._modes(groups, vals, lineno)
        self._feed_speed_tool(vals, ms, mgroups, lineno)
        if nonmodal == 40:
            self._dwell(vals, lineno)
        elif nonmodal in HOME_CODES:
            self.homes.run(nonmodal, vals, lineno)
        elif nonmodal is not None and nonmodal != 530:
            self.offsets.apply(nonmodal, vals, self.modal.pos, self.modal.scale)
        if axis_code:
            if motion is not None:
                self.cycles.reset_level()
                moves.move(motion, {}, lineno)  # G80: cancels the motion mode
        elif (motion if motion is not None else self.modal.motion) in CYCLES:
            if motion is not None or not _MOVE.isdisjoint(vals):
                self._cycle(motion if motion is not None else self.modal.motion, vals, lineno)
        elif motion is not None or not _MOVE.isdisjoint(vals):
            self.cycles.reset_level()
            if nonmodal == 530:
                self._need_straight(motion)
            if (motion if motion is not None else self.modal.motion) in PROBE_CODE10:
                self.probing.probe(motion or self.modal.motion, vals, lineno)  # type: ignore
                if self.probing.set_parameters(self.params.set):
                    self.mark(lineno + 1)  # a probing run's stretch starts after it
            else:
                moves.move(motion, vals, lineno, machine=nonmodal == 530)
        stop = mgroups.get("stopping")
        if stop is not None:
            end = self.outputs.program_end(self.modal.pos, self._src(lineno)) \
                if stop in (2, 30) else None
            if end is not None:
                self.out.append(end)
            self.out.append(StopBlock(_STOPS[stop], self.modal.pos, self._src(lineno)))
            self.ended = stop in (2, 30)
            if self.ended and self.offsets.table.active != 1:
                self.offsets.select_system(540)  # LinuxCNC: M2/M30 go back to G54 (G92 stays)

    def fast(self, code: int, vals: dict[str, float], lineno: int) -> bool:
        """G0 G1 G2 G3 lines with only X Y Z F (and I J R for arcs): most lines of a program.

        `code` is the line's one G code (code10) or -1. Same result as the general path,
        without its group and letter bookkeeping; False means "use the general path"."""
        modal = self.modal
        if code >= 0:
            mode = code
            if mode not in _FAST_MOTIONS:
                return False
        else:
            mode = modal.motion
            if mode not in _FAST_MOTIONS or _AXES.isdisjoint(vals):
                return False
        if not (_ARC_LETTERS if mode >= 20 else _LINE_LETTERS).issuperset(vals):
            return False
        if "F" in vals:
            if vals["F"] < 0 or 0 < vals["F"] * modal.scale < MIN_FEED_MM_MIN:
                return False  # the general path reports it
            modal.feed_mm_s = vals["F"] * modal.scale / 60.0
        self.cycles.initial_z = None  # any other motion ends a cycle's initial level
        self.moves.move(code if code >= 0 else None, vals, lineno)
        return True

    def _cycle(self, code: int, vals: dict[str, float], lineno: int) -> None:
        if self.modal.plane != 170:
            raise WordError(g_name(code), f"{g_name(code)}: canned cycles run in the XY plane "
                                          f"(G17) only")
        new = self.modal.motion != code
        self.modal.motion = code
        self.cycles.run(code, vals, lineno, new)

    def warn(self, lineno: int, message: str, prefix: str | None = None) -> None:
        """Note something accepted that LinuxCNC refuses (the first MAX_WARNINGS, no repeats)."""
        if self.track is None:
            return
        warnings = self.track.warnings
        path, line = self.locate(lineno)
        if prefix is None:
            prefix = f"line {line}" if path == self.path else f"{path}:{line}"
        text = f"{prefix}: {message}"
        if len(warnings) < MAX_WARNINGS and text not in warnings:
            warnings.append(text)

    def warn_word(self, lineno: int, word: str, message: str) -> None:
        """Warn about a word accepted beyond LinuxCNC, naming the file, line, word and rule."""
        path, line = self.locate(lineno)
        self.warn(lineno, f"{word}: {message}", prefix=f"{path}:{line}")

    def _src(self, lineno: int) -> Source:
        return Source(self.path, lineno, lineno)

    def _need_straight(self, motion: int | None) -> None:
        mode = motion if motion is not None else self.modal.motion
        if mode not in (0, 10):
            raise WordError("G53", "G53 (machine coordinates) needs G0 or G1 in force")

    def mark(self, line: int) -> None:
        """Run from `line`: note the state here and drop what the earlier lines produced
        (but for the outputs they set, which are set again here)."""
        self.out.clear()
        restore = self.outputs.restore_block(self.modal.pos, self._src(line))
        if restore is not None:
            self.out.append(restore)
        self.mark_pending = None
        modal = self.modal
        x, y, z = modal.pos
        self.at_line = LineState(
            line=line, position_mm=(float(x), float(y), float(z)), offsets=self.offsets.table,
            feed_mm_s=modal.feed_mm_s, absolute=modal.absolute, inch=modal.scale != 1.0,
            motion=None if modal.motion is None else g_name(modal.motion),
            path_control=modal.path_control, spindle=f"M{self.spindle_code}",
            spindle_rpm=self._rpm(), coolant=self.coolant, tool=self.tools.selected)

    def inside_nurbs(self, line: int) -> NcError:
        """Run from a line inside a multi-line NURBS block: an error naming that line."""
        nurbs = self.moves.nurbs
        first = nurbs.first_line
        return NcError(self.path, line, 1, nurbs.kind,
                       f"cannot run from line {line}: it is inside the {nurbs.kind} NURBS "
                       f"block that starts at line {first}; run from line {first}")

    def _modes(self, groups: dict[str, int], vals: dict[str, float], lineno: int) -> None:
        if "canned return" in groups:
            self.cycles.retract_to_r = groups["canned return"] == 990
        if "units" in groups:
            scale = MM_PER_INCH if groups["units"] == 200 else 1.0
            # The F number stays and now means units per minute of the new units, as LinuxCNC
            # reads an F set before G20 (its feed is kept in the program's current units).
            self.modal.feed_mm_s *= scale / self.modal.scale
            self.modal.scale = scale
        if "distance" in groups:
            self.modal.absolute = groups["distance"] == 900
        if "arc distance" in groups:
            self.modal.arc_absolute = groups["arc distance"] == 901
        if "plane" in groups:
            self.modal.plane = groups["plane"]
        if "spindle mode" in groups:
            self.css = groups["spindle mode"] == 960
        if "coordinate system" in groups:
            self.offsets.select_system(groups["coordinate system"])
        path = groups.get("path control")
        if path == 610:
            self.modal.path_control = PathControl(PathMode.EXACT_STOP)
        elif path == 611:
            self.modal.path_control = PathControl(PathMode.EXACT_PATH)
        elif path == 640:
            self.modal.path_control = PathControl(PathMode.BLEND, self._tol(vals, "P"),
                                            self._tol(vals, "Q"))
        length = groups.get("tool length")
        if length == 430:
            self.tools.g43(vals)
        elif length == 431:
            self.tools.g43_1(vals)
        elif length == 490:
            self.tools.g49(vals.get("H"), lineno)
        # G40, G94, G98/G99 and G97 change nothing in phcnc's model; accepted for CAM headers.

    def _tol(self, vals: dict[str, float], letter: str) -> float | None:
        if letter not in vals:
            return None
        if vals[letter] < 0:
            raise WordError(letter, f"G64 {letter} tolerance must not be negative")
        return vals[letter] * self.modal.scale

    def _feed_speed_tool(self, vals: dict[str, float], ms: list[int], mgroups: dict[str, int],
                         lineno: int) -> None:
        # F is read in the units in force after this line's G20/G21.
        if "F" in vals:
            if vals["F"] < 0:
                raise WordError("F", "negative feed rate")
            if 0 < vals["F"] * self.modal.scale < MIN_FEED_MM_MIN:
                raise WordError("F", f"feed F{vals['F']:g} is below the minimum of "
                                     f"{MIN_FEED_MM_MIN:g} mm/min (as grbl's)")
            self.modal.feed_mm_s = vals["F"] * self.modal.scale / 60.0
        if "S" in vals:
            if vals["S"] < 0:
                raise WordError("S", "negative spindle speed")
            self.spindle_rpm = self._clamped_rpm(vals["S"], lineno)
        if "T" in vals:
            self.tools.select(vals["T"])
        if mgroups.get("tool change") == 61:
            self.tools.set_loaded(vals.get("Q"))
        elif "tool change" in mgroups:
            stop = self.outputs.spindle_off(self.modal.pos, self._src(lineno))
            if stop is not None:  # M6 stops the spindle (an output), then the change
                self.out.append(stop)
                self.spindle_on, self.spindle_code = False, 5
            self.tools.change(lineno)
        spindle = mgroups.get("spindle")
        if spindle is not None:
            self.spindle_on = spindle != 5
            self.spindle_code = spindle
        for m in ms:
            if m in MODAL_SAVE_CODES:  # after the spindle, before coolant (LinuxCNC's order)
                self.contexts.run(m, lineno)
        for m in ms:
            if m in (48, 49):
                self._override(m == 48, lineno)
            if m in (7, 8, 9):
                self.coolant = () if m == 9 else tuple(sorted({*self.coolant, f"M{m}"}))
        block = self.outputs.line_block(ms, vals, self._rpm(), self.modal.pos,
                                        self._src(lineno))
        if block is not None:  # set at rest before the line's move
            self.out.append(block)
        synced = self.outputs.synced_block(self.modal.pos, self._src(lineno))
        if synced is not None:  # M62/M63/M67: with the next move (this line's, if it has one)
            self.out.append(synced)

    def _clamped_rpm(self, rpm: float, lineno: int) -> float:
        """S above io.spindle.max_rpm runs at that maximum, as grbl clamps S to its $30 (under
        G96, S is a surface speed and is not clamped)."""
        top = self.config.io.spindle.max_rpm
        if self.css or rpm <= top:
            return rpm
        self.warn_word(lineno, f"S{rpm:g}", f"above the spindle's {top:g} rpm "
                                            f"(io.spindle.max_rpm): clamped to {top:g} rpm "
                                            "(grbl's rule: S is clamped to its maximum)")
        return top

    def _override(self, enabled: bool, lineno: int) -> None:
        """M48/M49 (LinuxCNC): feed override on/off from this line; the stretches with it off
        go to `track` for the motion controller, which then runs those lines at 100 %."""
        if self.track is None:
            return
        spans = self.track.override_off_lines
        open_span = bool(spans) and spans[-1][1] < 0
        if not enabled and not open_span:
            spans.append([lineno, -1])
        elif enabled and open_span:
            spans[-1][1] = lineno

    def _rpm(self) -> float | None:
        """Spindle speed for AuxBlock: None under G96, where S is a surface speed."""
        return None if self.css else self.spindle_rpm

    def _dwell(self, vals: dict[str, float], lineno: int) -> None:
        if "P" not in vals:
            raise WordError("G4", "G4 dwell needs P (seconds)")
        if vals["P"] < 0:
            raise WordError("P", "G4 dwell time must not be negative")
        if vals["P"] > MAX_BLOCK_S:
            raise WordError("P", f"G4 dwell of {vals['P']:.6g} s is longer than "
                                 f"{MAX_BLOCK_S / 3600:g} h")
        self.out.append(DwellBlock(vals["P"], self.modal.pos, self._src(lineno)))

    def finish_program(self, lineno: int) -> None:
        """End of file: an open G6.2 block ends here; an open G5.2 block is an error."""
        nurbs = self.moves.nurbs
        if nurbs is None:
            return
        if nurbs.kind == "G5.2":
            raise NcError(self.path, nurbs.first_line, 1, "G5.2",
                          "G5.2 NURBS block not closed by G5.3 before the end of the program")
        self.moves.end_nurbs()


def _drop_g80(gs: list[int]) -> list[int]:
    """`G0 G80` (the common safety line): another motion code on the line cancels the cycle
    anyway, so LinuxCNC accepts both; G80 is dropped and the other code is in force."""
    others = [g for g in gs if g != 800 and G_GROUP.get(g) == "motion"]
    return [g for g in gs if g != 800] if others else gs


def _groups(codes: list[int], table: dict[int, str], name) -> dict[str, int]:  # noqa: ANN001
    """Group -> code for one line; two codes of one modal group are an error."""
    groups: dict[str, int] = {}
    for code in codes:
        group = table[code]
        if group in groups:
            if group == "coolant" and {groups[group], code} == {7, 8}:
                continue  # mist and flood together are fine
            raise WordError(name(code), f"{name(code)} and {name(groups[group])} are both in "
                                        f"the {group} modal group")
        groups[group] = code
    return groups


def _check_letters(groups: dict[str, int], vals: dict[str, float], motion: int | None,
                   ms: list[int]) -> None:
    """Every value word must be used by a code of the line (LinuxCNC's 'word with no G code')."""
    allowed = set(_ALWAYS)
    for m in ms:
        allowed |= M_LETTERS.get(m, frozenset())
    for code in groups.values():
        allowed |= _USES.get(code, frozenset())
    if motion is not None and not _MOVE.isdisjoint(vals):
        allowed |= _USES.get(motion, frozenset())
    unused = vals.keys() - allowed
    if unused:
        letter = min(unused, key="XYZ@^IJKRPQELHFST".index)
        if letter in _MOVE:
            raise WordError(letter, f"{letter} word with no motion mode (G0, G1, G2, G3) "
                                    f"in force")
        if letter == "E":  # most often X1e3: G-code numbers have no exponent
            raise WordError(letter, "E word with no M67 or M68 on the line (nor exponents: "
                                    "write 1e3 as 1000)")
        raise WordError(letter, f"{letter} word with no G code on the line that uses it")
