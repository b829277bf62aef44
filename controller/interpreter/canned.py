"""Canned cycles G73 G81 G82 G83 G85 G89 in the XY plane, as LinuxCNC's interp_cycles.cc runs
them: straight traverses, feeds and dwells, with G98/G99 retract and R, Q, P, L."""

from __future__ import annotations

from controller.blocks import DwellBlock, PathControl, PathMode, Source
from controller.interpreter.codes import WordError, g_name
from controller.interpreter.modal import Modal
from controller.interpreter.moves import Moves
from controller.interpreter.polar import cycle_polar, cycle_step, has_polar

CYCLES = frozenset((730, 810, 820, 830, 850, 890))  # code10 of the supported cycles
_NEEDS_Q = frozenset((730, 830))
_NEEDS_P = frozenset((820, 890))
PECK_BACKOFF_IN = 0.010  # LinuxCNC's G83_RAPID_DELTA: G73 backs off, G83 comes back, this far
_MAX_PECKS = 100_000


class CannedCycles:
    """Runs a cycle line through `moves` (which moves `modal.pos` and appends the blocks).

    Keeps the sticky values LinuxCNC keeps between cycle lines: Z, R, Q and P (program
    units as written), and the retract mode (G98: to the Z where the cycle started, the
    default; G99: to R)."""

    def __init__(self, modal: Modal, moves: Moves, path: str) -> None:
        self.modal = modal
        self.moves = moves
        self.path = path
        self.retract_to_r = False
        self.z: float | None = None
        self.r: float | None = None
        self.q: float | None = None
        self.p: float | None = None
        # LinuxCNC 2.9's initial level: the Z (program units) where the first cycle line since
        # the last other motion started; G98 retracts there. None until a cycle line runs.
        self.initial_z: float | None = None

    def run(self, code: int, vals: dict[str, float], lineno: int, new: bool) -> None:
        """One cycle line; `new`: the cycle was not in force before this line (then Z and R,
        and Q or P where the cycle needs them, must be on the line)."""
        name = g_name(code)
        z = self._sticky("Z", vals, self.z, new, name)
        r = self._sticky("R", vals, self.r, new, name)
        q = self._sticky("Q", vals, self.q, new, name) if code in _NEEDS_Q else None
        p = self._sticky("P", vals, self.p, new, name) if code in _NEEDS_P else None
        repeats = self._repeats(vals)
        if q is not None and q <= 0.0:
            raise WordError("Q", f"{name} peck Q must be positive")
        if p is not None and p < 0.0:
            raise WordError("P", f"{name} dwell P must not be negative")
        moves, modal = self.moves, self.modal
        x0, y0, z0 = (moves.program(i, modal.pos[i]) for i in range(3))
        if self.initial_z is None:
            self.initial_z = z0
        old_z = self.initial_z
        if modal.absolute:
            dx = dy = 0.0
            r_z, bottom = r, z
            x, y = vals.get("X", x0), vals.get("Y", y0)
        else:  # G91: R from the current Z, Z from R, X Y an increment for every repeat
            dx, dy = vals.get("X", 0.0), vals.get("Y", 0.0)
            r_z = r + old_z
            bottom = r_z + z
            x, y = x0, y0
        polar = (0.0, 0.0)  # G91 @ ^: the radius and angle every repeat adds
        if has_polar(vals):
            (x, y), polar = cycle_polar(vals, x0, y0, modal.absolute)
        if r_z < bottom:
            raise WordError("R", f"{name}: the R plane ({r_z:g}) is below the bottom Z "
                                 f"({bottom:g})")
        self.z, self.r, self.q, self.p = z, r, q if q is not None else self.q, \
            p if p is not None else self.p
        saved = modal.path_control
        modal.path_control = PathControl(PathMode.EXACT_PATH)  # LinuxCNC: G61.1 in cycles
        try:
            self._cycles(code, lineno, (x, y), (dx, dy, *polar), (old_z, z0, r_z, bottom), q,
                         p, repeats)
        finally:
            modal.path_control = saved

    def _cycles(self, code: int, lineno: int, xy: tuple[float, float],
                step: tuple[float, float, float, float], heights: tuple[float, float, float, float],
                q: float | None, p: float | None, repeats: int) -> None:
        """LinuxCNC 2.9's CYCLE_MACRO: up to R first if the initial level is below it; the first
        hole is reached at the current height, the others at the clear height. `step`: what
        each repeat adds, X Y and then (G91 @ ^) the radius and the angle (radians)."""
        x, y = xy
        old_z, z_now, r_z, bottom = heights
        if old_z < r_z:  # first straight up to R where the tool stands
            here = self.modal.pos
            self._go(self.moves.program(0, here[0]), self.moves.program(1, here[1]), r_z, True,
                     lineno)
            old_z = z_now = r_z
        clear = r_z if self.retract_to_r else old_z
        for n in range(repeats):
            x, y = x + step[0], y + step[1]
            if step[2] or step[3]:
                x, y = cycle_step(x, y, step[2:])
            if n == 0 and z_now > r_z:
                self._go(x, y, z_now, True, lineno)
                self._go(x, y, r_z, True, lineno)
            else:
                self._go(x, y, clear, True, lineno)
                if clear > r_z:
                    self._go(x, y, r_z, True, lineno)
            self._body(code, lineno, x, y, r_z, clear, bottom, q, p)

    def _body(self, code: int, lineno: int, x: float, y: float, r_z: float, clear: float,
              bottom: float, q: float | None, p: float | None) -> None:
        if code in _NEEDS_Q:
            self._pecks(code, lineno, x, y, r_z, clear, bottom, q)  # type: ignore[arg-type]
            return
        self._go(x, y, bottom, False, lineno)
        if p is not None:
            self._dwell(p, lineno)
        if code == 850:  # G85 feeds out to R, then goes on at traverse
            self._go(x, y, r_z, False, lineno)
        self._go(x, y, clear, code in (810, 820, 850), lineno)  # G89 feeds out

    def _pecks(self, code: int, lineno: int, x: float, y: float, r_z: float, clear: float,
               bottom: float, q: float) -> None:
        backoff = PECK_BACKOFF_IN * (1.0 if self.modal.scale != 1.0 else 25.4)
        if (r_z - bottom) / q > _MAX_PECKS:
            raise WordError("Q", f"{g_name(code)}: more than {_MAX_PECKS} pecks of Q{q:g}")
        depth = r_z - q
        while depth > bottom:
            self._go(x, y, depth, False, lineno)
            if code == 830:  # G83: out to R to clear the chips, back down to above the bottom
                self._go(x, y, r_z, True, lineno)
            self._go(x, y, depth + backoff, True, lineno)
            depth -= q
        self._go(x, y, bottom, False, lineno)
        self._go(x, y, clear, True, lineno)

    def reset_level(self) -> None:
        """A motion other than a cycle ran: the next cycle line sets a new initial level."""
        self.initial_z = None

    def _go(self, x: float, y: float, z: float, rapid: bool, lineno: int) -> None:
        moves = self.moves
        end = (moves.machine(0, x), moves.machine(1, y), moves.machine(2, z))
        moves.line_to(end, rapid, lineno, self.modal.motion or 810)

    def _dwell(self, seconds: float, lineno: int) -> None:
        self.moves.out.append(DwellBlock(seconds, self.modal.pos,
                                         Source(self.path, lineno, lineno)))

    def _sticky(self, letter: str, vals: dict[str, float], kept: float | None, new: bool,
                name: str) -> float:
        if letter in vals:
            return vals[letter]
        if kept is None or new:
            raise WordError(name, f"{name} needs {letter} on the line that starts it")
        return kept

    def _repeats(self, vals: dict[str, float]) -> int:
        count = vals.get("L", 1.0)
        if count < 1 or count != int(count):
            raise WordError("L", "canned cycle L (repeats) must be a positive integer")
        if count > 10_000:
            raise WordError("L", "canned cycle L (repeats) over 10000")
        return int(count)
