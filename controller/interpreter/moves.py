"""Motion of one line: G0/G1 lines, G2/G3 arcs (plane_arcs), and the G5.2/G6.2 NURBS blocks."""

from __future__ import annotations

import math
from collections.abc import Callable

from controller.blocks import LineBlock, NcBlock, Source
from controller.config import MachineConfig
from controller.interpreter.codes import WordError, g_name
from controller.interpreter.modal import Modal
from controller.interpreter.nurbs_blocks import NurbsCollector, check_order, split_at_corners
from controller.interpreter.plane_arcs import arc_block
from controller.interpreter.polar import has_polar, polar_xy
from controller.interpreter.splines import quadratic_block, quadratic_control
from controller.interpreter.work_offsets import WorkOffsets

# G6.2's first control point must be the current position within this: a drive reports whole
# pulses (1 um), so a program that ended at Y0.00059 stands at Y0.001 when run again.
SAME_POINT_MM = 2e-3
_G6_LETTERS = frozenset("XYZRK")
_G6_POINT = frozenset("XYRK")  # the words of a G6.2 control point or knot line
_AXES = frozenset("XYZ@^")  # the words that name an end point (@ ^: polar.py)


class Moves:
    """The motion words of a line: G0/G1 lines, G2/G3 arcs, G5.2/G6.2 NURBS blocks.

    Reads the shared `modal` state and the work origin of `offsets`, moves `modal.pos` and
    appends the blocks it builds to `out` (the list InterpState hands on). Owns the NURBS
    block being collected."""

    def __init__(self, modal: Modal, offsets: WorkOffsets, config: MachineConfig, path: str,
                 out: list[NcBlock]) -> None:
        self.modal = modal
        self.offsets = offsets
        self.config = config
        self.path = path
        self.out = out
        self.has_z = config.has_axis("z")
        self.rapid_mm_s = config.interpolator.rapid_feed_mm_s
        self.max_feed_mm_s = config.interpolator.max_feed_mm_s  # (config is frozen)
        self.nurbs: NurbsCollector | None = None  # the block of an open G5.2 or G6.2
        gcode = config.gcode
        self.default_feed_mm_min = gcode.default_feed_mm_min
        # grbl's power-up G0: the modal motion until the program's first motion code
        self.power_up_g0 = gcode.power_up_motion == "G0"
        if self.power_up_g0:
            modal.motion = 0
        # (lineno, word, message): a word accepted beyond LinuxCNC; InterpState's warn_word
        self.warn_word: Callable[[int, str, str], None] = lambda lineno, word, message: None

    def move(self, motion: int | None, vals: dict[str, float], lineno: int,
             machine: bool = False) -> None:
        """The line's motion; `machine`: its X Y Z are machine coordinates (G53)."""
        modal = self.modal
        if motion is not None and motion != 51:  # G5.1 leaves the motion mode as it was
            modal.motion = None if motion in (800, 53) else motion
            self.power_up_g0 = False
        elif motion is None and self.power_up_g0 and modal.motion == 0:
            self._warn_power_up(vals, lineno)
            self.power_up_g0 = False  # said once: the next lines follow the same G0
        mode = modal.motion if motion is None else motion
        if mode == 800 and not _AXES.intersection(vals):
            return  # G80 alone cancels the motion mode
        if mode is None or mode == 800:
            raise WordError(next((w for w in "XYZ@^" if w in vals), "X"),
                            "axis word with no motion mode (G0, G1, G2, G3) in force")
        if mode == 53:
            raise WordError("G5.3", "G5.3 without an open G5.2 block")
        if mode in (52, 62):
            self._start_nurbs(mode, vals, lineno)
            return
        if mode == 51:
            self._quadratic(vals, lineno)
            return
        end = self._end_point(vals, machine)
        if mode == 0:
            self._line(end, True, lineno)
        elif mode == 10:
            self._need_feed(motion, lineno)
            self._line(end, False, lineno)
        else:
            self._need_feed(motion, lineno)
            self._arc(mode == 20, end, vals, lineno, inherited=motion is None)

    def _need_feed(self, motion: int | None, lineno: int) -> None:
        if self.modal.feed_mm_s > 0.0:
            return
        word = g_name(motion if motion is not None else self.modal.motion or 10)
        if self.default_feed_mm_min is None:
            raise WordError(word, f"{word} feed move with no feed rate: program F first")
        self.modal.feed_mm_s = self.default_feed_mm_min / 60.0
        self.warn_word(lineno, word, f"no F programmed yet: moves at "
                                     f"gcode.default_feed_mm_min = {self.default_feed_mm_min:g} "
                                     f"mm/min (Klipper's and Marlin's rule; LinuxCNC and grbl "
                                     f"refuse)")

    def _warn_power_up(self, vals: dict[str, float], lineno: int) -> None:
        word = next((a for a in "XYZ@^" if a in vals), "G0")
        self.warn_word(lineno, word, "no motion mode programmed yet: moves at rapid, as G0 "
                                     "(gcode.power_up_motion: G0, grbl's power-up mode; "
                                     "LinuxCNC refuses)")

    def _end_point(self, vals: dict[str, float],
                   machine: bool = False) -> tuple[float, float, float]:
        modal = self.modal
        if has_polar(vals):
            return self._polar_end(vals)
        x, y, z = modal.pos
        s = modal.scale
        o = self.offsets.origin
        if modal.absolute and (o is None or machine):
            x = vals["X"] * s if "X" in vals else x
            y = vals["Y"] * s if "Y" in vals else y
            z = vals["Z"] * s if "Z" in vals else z
        elif modal.absolute:
            x = vals["X"] * s + o[0] if "X" in vals else x
            y = vals["Y"] * s + o[1] if "Y" in vals else y
            z = vals["Z"] * s + o[2] if "Z" in vals else z
        else:
            x += vals.get("X", 0.0) * s
            y += vals.get("Y", 0.0) * s
            z += vals.get("Z", 0.0) * s
        if z != modal.pos[2] and not self.has_z:
            raise WordError("Z", f"Z move on a machine without a Z axis "
                                 f"(config '{self.config.name}')")
        return x, y, z

    def _polar_end(self, vals: dict[str, float]) -> tuple[float, float, float]:
        """The end point of a line with `@` or `^` (polar.py): X Y about the work origin, Z as
        the line's Z word says."""
        here = (self._program(0, self.modal.pos[0]), self._program(1, self.modal.pos[1]))
        x, y = polar_xy(vals, *here, self.modal.absolute)
        z_only = {k: v for k, v in vals.items() if k == "Z"}
        z = self._end_point(z_only)[2]
        return self._machine(0, x), self._machine(1, y), z

    def line_to(self, end: tuple[float, float, float], rapid: bool, lineno: int,
                code: int) -> None:
        """A straight move to `end` (machine mm) made by `code` (a canned cycle, G28, G30)."""
        if end[2] != self.modal.pos[2] and not self.has_z:
            raise WordError(g_name(code), f"{g_name(code)} moves Z on a machine without a Z "
                                          f"axis (config '{self.config.name}')")
        if not rapid:
            self._need_feed(code, lineno)
        self._line(end, rapid, lineno)

    def end_point(self, vals: dict[str, float]) -> tuple[float, float, float]:
        """The machine point the line's X Y Z name (G90/G91, work offsets, units)."""
        return self._end_point(vals)

    def machine(self, axis: int, value: float) -> float:
        """An absolute program coordinate (program units) in machine mm."""
        return self._machine(axis, value)

    def program(self, axis: int, mm: float) -> float:
        """A machine coordinate (mm) in the program's frame and units."""
        return self._program(axis, mm)

    def _line(self, end: tuple[float, float, float], rapid: bool, lineno: int) -> None:
        modal = self.modal
        if end == modal.pos:
            return  # a zero-length move changes nothing
        feed = self.rapid_mm_s if rapid else modal.feed_mm_s
        block = LineBlock(modal.pos, end, feed, rapid, modal.path_control,
                          Source(self.path, lineno, lineno))
        cap = self.max_feed_mm_s
        cap = cap if cap < feed else feed  # _capped(feed) inline: this runs for every G1 line
        # math.dist is within a few ulps of the length (a numpy norm): only a move near the
        # limit needs that, and a G1 line of a long program costs no numpy call.
        if math.dist(modal.pos, end) > cap * MAX_BLOCK_S * (1.0 - 1e-9):
            _within_a_day(block.length_mm, cap, "F")
        self.out.append(block)
        modal.pos = end

    def _arc(self, clockwise: bool, end: tuple[float, float, float], vals: dict[str, float],
             lineno: int, inherited: bool = False) -> None:
        modal = self.modal
        try:
            block = arc_block(modal, self.offsets.origin, self.has_z, self.config.name,
                              clockwise, end, vals, Source(self.path, lineno, lineno))
        except WordError as err:
            if not (inherited and err.message.startswith("arc needs")):
                raise
            # X Y alone after a G2 line: most often a straight move meant (a G1 left out)
            raise WordError(err.word, f"{err.word} is in force from an earlier line: "
                                      f"{err.message} (a straight move needs G1)") from None
        _within_a_day(block.length_mm, self._capped(modal.feed_mm_s), "P" if block.turns else "F")
        self.out.append(block)
        modal.pos = end

    def _pulse_mm(self) -> float:
        return min(a.pulse_mm for a in self.config.axes)

    def _capped(self, feed_mm_s: float) -> float:
        cap = self.max_feed_mm_s
        return cap if cap < feed_mm_s else feed_mm_s  # min(feed_mm_s, cap), without its call

    def _machine(self, axis: int, value: float) -> float:
        """An absolute program coordinate (program units) in machine mm."""
        mm = value * self.modal.scale
        origin = self.offsets.origin
        return mm if origin is None else mm + origin[axis]

    def _program(self, axis: int, mm: float) -> float:
        """A machine coordinate (mm) in the program's frame and units."""
        origin = self.offsets.origin
        return (mm if origin is None else mm - origin[axis]) / self.modal.scale

    def _quadratic(self, vals: dict[str, float], lineno: int) -> None:
        """G5.1: one quadratic B-spline, the NURBS of order 3 through the current point, the
        control point start + I J and the end point (weights 1). As in LinuxCNC, G5.1 acts on
        its own line only: the motion mode in force before it stays."""
        self._need_feed(51, lineno)
        start = self.modal.pos
        control = quadratic_control(self.modal, vals)
        end = self._end_point(vals)
        if end == start and control[:2] == start[:2]:
            return  # no motion, as a G1 to where the tool stands
        block = quadratic_block(start, control, end, self.modal, self._pulse_mm(),
                                self.config.interpolator.max_feed_mm_s,
                                Source(self.path, lineno, lineno))
        self.out.extend(split_at_corners(block))
        self.modal.pos = end

    # ---- NURBS ------------------------------------------------------------------------------
    def _start_nurbs(self, mode: int, vals: dict[str, float], lineno: int) -> None:
        name = g_name(mode)
        if not self.modal.absolute:
            raise WordError(name, f"{name} NURBS in incremental mode (G91) is not supported")
        self._need_feed(mode, lineno)
        if "Z" in vals and self._machine(2, vals["Z"]) != self.modal.pos[2]:
            raise WordError("Z", "NURBS must stay at constant Z (no Z motion)")
        x0, y0, z0 = self.modal.pos
        if mode == 52:
            self._start_g5(vals, lineno, x0, y0, z0)
        else:
            self._start_g6(vals, lineno, x0, y0, z0)
        self.modal.motion = None  # after the NURBS block, a new motion code is needed

    def _start_g5(self, vals: dict[str, float], lineno: int, x0: float, y0: float,
                  z0: float) -> None:
        order = check_order(vals["L"], "L") if "L" in vals else 3
        has_xy = _xy_flags(vals)
        w0 = vals.get("P", 1.0) if not has_xy else 1.0  # LinuxCNC: P alone weights point 0
        self.nurbs = NurbsCollector("G5.2", order, x0, y0, w0, z0, self.modal.feed_mm_s,
                                    self.modal.path_control, self.path, lineno,
                                    self._pulse_mm())
        if has_xy:
            self._g5_point(vals, lineno)

    def _g5_point(self, vals: dict[str, float], lineno: int) -> None:
        if "P" not in vals:
            raise WordError("X", "G5.2 control point needs a weight P")
        self.nurbs.add_point(self._machine(0, vals["X"]), self._machine(1, vals["Y"]), vals["P"],
                             lineno)

    def _start_g6(self, vals: dict[str, float], lineno: int, x0: float, y0: float,
                  z0: float) -> None:
        if "P" not in vals:
            raise WordError("G6.2", "G6.2 needs the order P on its first line")
        order = check_order(vals["P"], "P")
        if "K" not in vals:
            raise WordError("G6.2", "G6.2 control point needs its knot K")
        x = self._machine(0, vals["X"]) if "X" in vals else x0
        y = self._machine(1, vals["Y"]) if "Y" in vals else y0
        if abs(x - x0) > SAME_POINT_MM or abs(y - y0) > SAME_POINT_MM:
            raise WordError("X" if "X" in vals else "Y",
                            f"the first G6.2 control point must be the current position "
                            f"X{self._program(0, x0):.4f} Y{self._program(1, y0):.4f}")
        self.nurbs = NurbsCollector("G6.2", order, x0, y0, vals.get("R", 1.0), z0,
                                    self.modal.feed_mm_s, self.modal.path_control, self.path,
                                    lineno, self._pulse_mm())
        self.nurbs.add_knot(vals["K"], lineno, knot_only=False)

    def nurbs_line(self, gs: list[int], ms: list[int], vals: dict[str, float],
                   lineno: int) -> bool:
        """A line while a NURBS block is open. True if the line belonged to the block."""
        if self.nurbs.kind == "G5.2":
            self._g5_line(gs, ms, vals, lineno)
            return True
        if ms or any(g != 62 for g in gs) or "P" in vals or not _G6_LETTERS.issuperset(vals):
            self.end_nurbs()
            return False
        if "Z" in vals:
            raise WordError("Z", "NURBS must stay at constant Z (no Z motion)")
        if "X" in vals or "Y" in vals or "R" in vals:
            if "K" not in vals:
                raise WordError("X" if "X" in vals else "Y" if "Y" in vals else "R",
                                "G6.2 control point needs its knot K")
            self._g6_point(vals, lineno)
        elif "K" in vals:
            self.nurbs.add_knot(vals["K"], lineno, knot_only=True)
        return True

    def g6_line(self, code: int, vals: dict[str, float], lineno: int) -> bool:
        """A line of X Y R K words only (`code`: its one G code, -1 for none, or G6.2's 62; no
        M) while a block is open: most lines of a NURBS program, taken as nurbs_line takes
        them, without its checks of other words. False (nothing done) if the block is not a
        G6.2 or the line has another code or word or no K."""
        nurbs = self.nurbs
        if code not in (-1, 62) or nurbs.kind != "G6.2" or "K" not in vals:  # type: ignore[union-attr]
            return False
        if not _G6_POINT.issuperset(vals):
            return False
        if len(vals) == 1:
            nurbs.add_knot(vals["K"], lineno, knot_only=True)  # type: ignore[union-attr]
        else:
            self._g6_point(vals, lineno)
        return True

    def _g6_point(self, vals: dict[str, float], lineno: int) -> None:
        """A G6.2 control point (X Y R, any of them) and its knot K."""
        nurbs = self.nurbs
        last_x, last_y = nurbs.points[-1]  # type: ignore[union-attr]
        x = self._machine(0, vals["X"]) if "X" in vals else last_x
        y = self._machine(1, vals["Y"]) if "Y" in vals else last_y
        nurbs.add_point(x, y, vals.get("R", 1.0), lineno)  # type: ignore[union-attr]
        nurbs.add_knot(vals["K"], lineno, knot_only=False)  # type: ignore[union-attr]

    def _g5_line(self, gs: list[int], ms: list[int], vals: dict[str, float],
                 lineno: int) -> None:
        if gs == [53] and not ms and not vals:
            self.end_nurbs(lineno)
            return
        if "Z" in vals:
            raise WordError("Z", "NURBS must stay at constant Z (no Z motion)")
        if gs or ms or not {"X", "Y", "P"}.issuperset(vals):
            word = g_name(gs[0]) if gs else (f"M{ms[0]}" if ms else
                                             min(vals.keys() - {"X", "Y", "P"}))
            raise WordError(word, "only X Y P control points may stand between G5.2 and G5.3")
        if _xy_flags(vals):
            self._g5_point(vals, lineno)
        elif "P" in vals:
            raise WordError("P", "P without X and Y is only allowed for the first control point")

    def end_nurbs(self, end_line: int | None = None) -> None:
        block = self.nurbs.finish(end_line, self.config.interpolator.max_feed_mm_s)
        self.nurbs = None
        self.out.extend(split_at_corners(block))
        self.modal.pos = (*block.end[:2], self.modal.pos[2])


def _xy_flags(vals: dict[str, float]) -> bool:
    """True if X and Y are both given, False if neither; one alone is an error."""
    if ("X" in vals) != ("Y" in vals):
        raise WordError("X" if "X" in vals else "Y",
                        "NURBS control point needs both X and Y")
    return "X" in vals


MAX_BLOCK_S = 86_400.0  # one block of a day's motion or dwell: a typo, or a job for no machine


def _within_a_day(length_mm: float, feed_mm_s: float, word: str) -> None:
    """A move that takes over MAX_BLOCK_S at its feed is refused by the check (it planned
    without end: an arc of 1e6 turns at F1.5 took 120 years and all memory)."""
    if length_mm > feed_mm_s * MAX_BLOCK_S:
        raise WordError(word, f"this move of {length_mm:.6g} mm takes "
                              f"{length_mm / feed_mm_s:.3g} s at {feed_mm_s * 60:g} mm/min: "
                              f"more than {MAX_BLOCK_S / 3600:g} h in one block")
