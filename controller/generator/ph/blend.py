"""G1 corners between blocks: a PH quintic blend within the path tolerance (G64 P, else eps_max)."""

from __future__ import annotations

import math

import numpy as np

from controller.geometry.path import Piece, PieceKind, degenerate_end, end_tangent, make_piece
from controller.geometry.ph_quintic import PhQuintic
from controller.numeric import clamp

MAX_BLEND_ANGLE_RAD = math.radians(175.0)  # sharper reversals stop instead of looping round
MAX_SHARE = 0.45  # a blend takes at most this share of each neighbouring piece
BISECTIONS = 30
MIN_CUT_MM = 1e-4
CUT_TOL_MM = 1e-6  # a windowed NURBS cut's length, against a cut searched to 1 %


def _line_u(piece: Piece, s_path_mm: float) -> float:
    """Piece.u_at of a LINE piece at one arc length, in Python floats: the same operations as
    the arrays (LineCurve's u = s / length), without numpy's cost per call; G1 programs blend
    every joint, so this is on the planner's path once per line."""
    length = piece.curve.length_mm
    local = min(max(s_path_mm - piece.s0_mm, 0.0), piece.length_mm)
    u = (local + piece.u0 * length) / length
    return min(max(u, min(piece.u0, piece.u1)), max(piece.u0, piece.u1))


def _line_xy(piece: Piece, u: float) -> tuple[float, float, float, float]:
    """LineCurve.evaluate at one parameter: point and derivative."""
    (x0, y0), (x1, y1) = piece.curve.p0, piece.curve.p1  # type: ignore[attr-defined]
    dx, dy = x1 - x0, y1 - y0
    return x0 + u * dx, y0 + u * dy, dx, dy


def _point(piece: Piece, s_local: float) -> tuple[complex, complex]:
    """Point and unit tangent at a local arc length of a piece (from its start: a piece of a
    look-ahead window's prefix is chained, s0 > 0; the blocks' own pieces have s0 = 0)."""
    if piece.kind == PieceKind.LINE:
        x, y, dx, dy = _line_xy(piece, _line_u(piece, piece.s0_mm + s_local))
        t = complex(dx, dy)
        return complex(x, y), t / abs(t)
    u = piece.u_at(np.array([piece.s0_mm + s_local]))
    d = piece.curve.evaluate(u, 1)[:, 0]
    t = complex(d[1, 0], d[1, 1])
    return complex(d[0, 0], d[0, 1]), t / abs(t)


class _Side:
    """One piece of a joint, as each trial of the bisection needs it: the point and tangent at
    the cut and the programmed path between the cut and the joint (n points, or the two ends
    of a line). Piece.u_at with the curve's offset computed once, and point, tangent and path
    from one arc-length inversion and one evaluation (both are per element: the numbers are
    those of separate calls).

    by_parameter (a long program's windows): a NURBS side's cut is found by Newton on s(u) and
    its path sampled evenly in u, so that trials build no arc-length inverse (the inverse,
    built by intervals over 45 % of the piece for the first trial, was a quarter of the
    planning of distinct airfoils)."""

    def __init__(self, piece: Piece, at_end: bool, n: int = 64, by_parameter: bool = False
                 ) -> None:
        self.p, self.at_end, self.n = piece, at_end, n
        self.by_parameter = by_parameter and hasattr(piece.curve, "arc_length_table")
        self._u_near: dict[float, float] = {}
        if piece.kind != PieceKind.LINE:
            self.curve_s0 = piece.curve_s0_mm
            self.lo, self.hi = min(piece.u0, piece.u1), max(piece.u0, piece.u1)

    def _prime(self, s_path_mm: float) -> None:
        """A NURBS's arc-length inverse is built where first asked, by intervals, and how the
        intervals are grouped in one build moves its last bits (matrix products): build the
        cut's interval first, then the span's, as separate calls for the point and the span
        did (what u_of_s would do with the cut alone, without its evaluation)."""
        table = getattr(self.p.curve, "arc_length_table", None)
        if table is None:
            return
        local = min(max(s_path_mm - self.p.s0_mm, 0.0), self.p.length_mm)
        s = clamp(np.array([local + self.curve_s0]), 0.0, table.total_length_mm)
        table._inverse.ensure(s)  # noqa: SLF001

    def u_at(self, s_path_mm: np.ndarray) -> np.ndarray:
        p = self.p
        local = clamp(s_path_mm - p.s0_mm, 0.0, p.length_mm)
        return clamp(p.curve.u_of_s(local + self.curve_s0), self.lo, self.hi)

    def u_near(self, s_local_mm: float) -> float:
        """The parameter at an arc length inside the piece to CUT_TOL_MM (Newton on s(u),
        no inverse table): the blend starts wherever the trimmed piece ends, both at this
        parameter, so the cut's length need not be exact."""
        if s_local_mm not in self._u_near:  # the cut that fits was tried: trim there
            table = self.p.curve.arc_length_table  # type: ignore[attr-defined]
            self._u_near[s_local_mm] = table.u_of_s_scalar(self.curve_s0 + s_local_mm, self.lo,
                                                           self.hi, CUT_TOL_MM)
        return self._u_near[s_local_mm]

    def _edge_u(self) -> float:
        return self.p.u1 if self.at_end else self.p.u0

    def trial(self, cut_mm: float) -> tuple[complex, complex, np.ndarray]:
        """(point, unit tangent) at the cut, and the path from the cut to the joint (for the
        end of a piece) or from the joint to the cut (for its start)."""
        p = self.p
        s_cut = p.length_mm - cut_mm if self.at_end else cut_mm
        if p.kind == PieceKind.LINE:
            pt, t = _point(p, s_cut)
            ends = (p.length_mm - cut_mm, p.length_mm) if self.at_end else (0.0, cut_mm)
            pts = np.array([_line_xy(p, _line_u(p, p.s0_mm + s))[:2] for s in ends])
            return pt, t, pts
        if self.by_parameter:
            u_cut = self.u_near(s_cut)
            u = np.linspace(u_cut, self._edge_u(), self.n) if self.at_end else \
                np.linspace(self._edge_u(), u_cut, self.n)
        else:
            span = np.linspace(s_cut, p.length_mm, self.n) if self.at_end else \
                np.linspace(0.0, cut_mm, self.n)
            self._prime(p.s0_mm + s_cut)
            u = self.u_at(p.s0_mm + span)
        # The cut is the first point of the end's span and the last of the start's (linspace
        # returns its ends exactly).
        d = p.curve.evaluate(u, 1)
        k = 0 if self.at_end else -1
        t = complex(d[1, k, 0], d[1, k, 1])
        return complex(d[0, k, 0], d[0, k, 1]), t / abs(t), d[0]

    def tangent_at_joint(self) -> complex:
        """The unit tangent where the piece meets the other (at its end parameter when
        by_parameter, else at its end arc length, as the single run always did); the direction
        of travel where the curve's derivative vanishes there (a cusp)."""
        if self.p.kind != PieceKind.LINE and degenerate_end(self.p, self.at_end):
            x, y = end_tangent(self.p, self.at_end)
            return complex(x, y)
        if not self.by_parameter:
            return _point(self.p, self.p.length_mm if self.at_end else 0.0)[1]
        d = self.p.curve.evaluate(np.array([self._edge_u()]), 1)[1, 0]
        t = complex(d[0], d[1])
        return t / abs(t)

    def cut_u(self, cut_mm: float) -> float:
        """The parameter where the trimmed piece ends (at_end) or starts."""
        p = self.p
        if self.by_parameter:
            return self.u_near(p.length_mm - cut_mm if self.at_end else cut_mm)
        return _u_at(p, p.s0_mm + p.length_mm - cut_mm if self.at_end else p.s0_mm + cut_mm)


def deviation_mm(ph: PhQuintic, poly: np.ndarray, n: int = 65) -> float:
    """Largest distance from the blend to the programmed path it replaces (the polyline poly,
    (m, 2)). On x and y apart: each dot product, projection and squared distance as the sum
    of the same two products an einsum over (x, y) and a norm form, the square root taken of
    each point's least (sqrt is monotonic): the same number, at a fifth of the cost."""
    pts = ph.point(np.linspace(0.0, 1.0, n))
    if np.iscomplexobj(pts):
        px, py = pts.real[:, None], pts.imag[:, None]
    else:
        px, py = pts[:, 0, None], pts[:, 1, None]
    ax, ay = poly[:-1, 0], poly[:-1, 1]
    abx, aby = poly[1:, 0] - ax, poly[1:, 1] - ay
    t = np.clip(((px - ax) * abx + (py - ay) * aby) / np.maximum(abx * abx + aby * aby, 1e-300),
                0.0, 1.0)
    dx = px - (ax + t * abx)
    dy = py - (ay + t * aby)
    return float(np.sqrt((dx * dx + dy * dy).min(axis=1)).max())


def _trial(a: _Side, b: _Side, cut_mm: float) -> tuple[PhQuintic, float]:
    """The blend with this cut on both sides and its deviation from the path it replaces."""
    p0, t0, pa = a.trial(cut_mm)
    p5, t1, pb = b.trial(cut_mm)
    chord = abs(p5 - p0)
    ph = PhQuintic.hermite(p0, p5, t0 * chord, t1 * chord)
    return ph, deviation_mm(ph, np.vstack([pa, pb]))


def _fits(a: _Side, b: _Side, cut_mm: float, tol_mm: float) -> tuple[float, PhQuintic] | None:
    ph, deviation = _trial(a, b, cut_mm)
    return (cut_mm, ph) if deviation <= tol_mm else None


def _bisected(a: _Side, b: _Side, hi: float, tol_mm: float) -> tuple[float, PhQuintic] | None:
    """The largest cut below hi that fits, to BISECTIONS halvings (a single run's blends)."""
    best, lo = None, 0.0
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        trial = _fits(a, b, mid, tol_mm)
        if trial is None:
            hi = mid
        else:
            best, lo = trial, mid
    return best


def _power_guess(lo: float, dev_lo: float, hi: float, dev_hi: float, target: float) -> float:
    """The cut where the deviation reaches target, the deviation taken as c cut^p through the
    bracket's ends (p = 1 through zero while no cut has fitted: a corner's blend grows with
    its cut, a line's exactly so)."""
    if lo <= 0.0 or dev_lo <= 0.0:
        return hi * target / dev_hi
    p = math.log(dev_hi / dev_lo) / math.log(hi / lo)
    return lo * (target / dev_lo) ** (1.0 / p) if p > 0.2 else 0.5 * (lo + hi)


def _line_aim(t0: complex, t1: complex, tol_mm: float) -> float:
    """The cut at which the blend of two lines with these tangents meets tol_mm (a blend of
    lines scales with its cut, unit_blend.py): where a curved joint's search starts."""
    chord = abs(t0 + t1)
    if chord == 0.0:
        return math.inf
    unit = PhQuintic.hermite(-t0, t1, t0 * chord, t1 * chord)
    lines = np.array([[-t0.real, -t0.imag], [0.0, 0.0], [t1.real, t1.imag]])
    deviation = deviation_mm(unit, lines)
    return tol_mm / deviation if deviation > 0 else math.inf


def _searched(a: _Side, b: _Side, hi: float, tol_mm: float, precision: float,
              aim_mm: float) -> tuple[float, PhQuintic] | None:
    """The largest cut up to hi that fits, to `precision` of itself (a long program's
    windows). The first trial is at the cut that would fit were both sides lines (aim_mm),
    just under the tolerance; after a cut that does not fit, the deviation's power law aims
    again, and a guess outside the bracket halves it. A cut that fits is taken once its
    deviation is within `precision` of the tolerance: the deviation grows at least as fast
    as the cut at a corner (a line's exactly as fast), so the cut is then within `precision`
    of the largest. Otherwise the next trial steps just past it, which closes the bracket
    when it fails. 1 trial at a joint of lines, 2 at the airfoil's trailing edge (the lines'
    aim 2 % over, its power-law correction fitted) where halving took 11; hi, the share of
    the pieces, stays untried while nothing fails."""
    target = tol_mm * (1.0 - 0.5 * precision)
    best, lo, dev_lo, dev_hi = None, 0.0, 0.0, math.inf
    hi_failed = False  # hi is only the share of the pieces until a cut there does not fit
    guess, stepped = min(hi, aim_mm * (1.0 - 0.5 * precision)), False
    for _ in range(BISECTIONS):
        ph, deviation = _trial(a, b, guess)
        if deviation <= tol_mm:
            best, lo, dev_lo, stepped = (guess, ph), guess, deviation, False
            if deviation >= tol_mm * (1.0 - precision):
                break
        else:
            hi, dev_hi, hi_failed = guess, deviation, True
        if best is not None and (lo >= hi or hi_failed and hi - lo <= precision * lo):
            break
        if best is not None and not stepped:
            # just inside the precision, so that the bracket surely closes if it fails
            guess, stepped = min(lo * (1.0 + 0.999 * precision), hi), True
        elif not hi_failed:  # only fits so far: aim on from the last one, at least a step
            guess = min(hi, max(lo * target / dev_lo if dev_lo > 0 else hi,
                                lo * (1.0 + precision)))
        else:
            guess = _power_guess(lo, dev_lo, hi, dev_hi, target)
            if not lo < guess < hi:
                guess = 0.5 * (lo + hi)
    return best


def _u_at(p: Piece, s_path_mm: float) -> float:
    if p.kind == PieceKind.LINE:
        return _line_u(p, s_path_mm)
    return float(p.u_at(np.array([s_path_mm]))[0])


def _trimmed(p: Piece, u0: float, u1: float) -> Piece:
    """make_piece of the part [u0, u1] of p's curve."""
    return make_piece(p.kind, p.curve, u0, u1, 0.0, p.feed_mm_s, p.line, p.corner)


def blend_joint(a: Piece, b: Piece, tolerance_mm: float,
                precision: float = 0.0) -> tuple[Piece, Piece, Piece] | None:
    """(a trimmed, PH blend, b trimmed) with deviation <= tolerance, or None to stop there.

    The cut is bisected BISECTIONS times, or, with a precision, searched until it is within
    that share of the largest that fits (the windows of a long program: repeats.py)."""
    if a.kind == PieceKind.PH or b.kind == PieceKind.PH or tolerance_mm <= 0:
        return None
    by_parameter = bool(precision)
    side_a, side_b = _Side(a, True, by_parameter=by_parameter), \
        _Side(b, False, by_parameter=by_parameter)
    t0, t1 = side_a.tangent_at_joint(), side_b.tangent_at_joint()
    if abs(math.atan2((t1 / t0).imag, (t1 / t0).real)) > MAX_BLEND_ANGLE_RAD:
        return None
    hi = MAX_SHARE * min(a.length_mm, b.length_mm)
    if precision:
        best = _searched(side_a, side_b, hi, tolerance_mm, precision,
                         _line_aim(t0, t1, tolerance_mm))
    else:
        ph, dev_hi = _trial(side_a, side_b, hi)
        best = (hi, ph) if dev_hi <= tolerance_mm else \
            _bisected(side_a, side_b, hi, tolerance_mm)
    if best is None or best[0] < MIN_CUT_MM:
        return None
    cut, ph = best
    a_cut = _trimmed(a, a.u0, side_a.cut_u(cut))
    b_cut = _trimmed(b, side_b.cut_u(cut), b.u1)
    blend = Piece(PieceKind.PH, ph, 0.0, 1.0, 0.0, ph.length_mm, b.feed_mm_s, b.line)
    return a_cut, blend, b_cut
