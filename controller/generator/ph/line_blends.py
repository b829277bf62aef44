"""G1 line-to-line corners of a long program's windows, every joint of a window at once.

A joint's blend is its unit blend (unit_blend.py) scaled by the largest cut the tolerance and
MAX_SHARE of each line allow, exactly; blend.py bisects for it one trial at a time (~0.1 ms a
joint: a quarter of the planning of a G1 program). A single run's plans keep blend.py (bit
for bit as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.generator.ph.blend import MAX_BLEND_ANGLE_RAD, MAX_SHARE, MIN_CUT_MM
from controller.generator.ph.unit_blend import unit_blends
from controller.geometry.curves import LineCurve
from controller.geometry.path import Piece, PieceKind, new_piece
from controller.geometry.ph_quintic import PhQuintic

_SAFETY = 1.0 - 1e-9  # c D rounds: stay a hair inside the tolerance


@dataclass(frozen=True, eq=False, repr=False)
class LineJoints:
    """The joints between consecutive line blocks of a window, by the index of the block after
    the joint: turn angle, deviation of the unit blend (mm per mm of cut), its w coefficients
    (a PH quintic with cut c has w sqrt(c)) and whether the canonical interpolant is the one
    PhQuintic.hermite would choose (both end derivatives tame: turns up to ~160 degrees).
    Lists of Python numbers: they are read one joint at a time."""

    row: dict[int, int]
    angle_rad: list[float]
    unit_deviation: list[float]
    w_unit: list[tuple[complex, complex, complex]]
    canonical: list[bool]


def _unit_tangents(curves: list[object], is_line: list[bool]) -> np.ndarray:
    """Each line's unit tangent, complex (0 for a curve that is not a line): t / abs(t) of
    t = complex(dx, dy) as Python computes it, on arrays (abs is hypot in both, and the
    division by a real, taken as a complex, is (dx + dy 0) / |t| and (dy - dx 0) / |t|)."""
    ends = np.array([(*c.curve.p0, *c.curve.p1) if line else (0.0, 0.0, 1.0, 0.0)  # type: ignore[attr-defined]
                     for c, line in zip(curves, is_line, strict=True)], float).reshape(-1, 4)
    dx, dy = ends[:, 2] - ends[:, 0], ends[:, 3] - ends[:, 1]
    r = np.hypot(dx, dy)
    t = np.empty(len(ends), complex)
    t.real, t.imag = (dx + dy * 0.0) / r, (dy - dx * 0.0) / r
    return np.where(is_line, t, 0j)


def line_joints(curves: list[object]) -> LineJoints:
    """Every joint of two lines in a window's block curves (BlockCurve: .curve)."""
    is_line = [isinstance(c.curve, LineCurve) for c in curves]  # type: ignore[attr-defined]
    index = [i for i in range(1, len(curves)) if is_line[i - 1] and is_line[i]]
    # Each line's tangent once (a line between two others is in two joints); block_curve
    # makes no line shorter than a micrometre, so none has a zero tangent.
    tangent = _unit_tangents(curves, is_line)
    at = np.array(index, np.intp)
    t0, t1 = tangent[at - 1], tangent[at]
    w, deviation, canonical = unit_blends(t0, t1, MAX_BLEND_ANGLE_RAD)
    return LineJoints({i: k for k, i in enumerate(index)},
                      np.abs(np.angle(t1 * np.conj(t0))).tolist(), deviation.tolist(),
                      [tuple(r) for r in w.reshape(-1, 3).tolist()], canonical.tolist())


def blend_lines(a: Piece, b: Piece, tolerance_mm: float, joints: LineJoints,
                row: int) -> tuple[Piece, Piece, Piece] | None:
    """(a trimmed, PH blend, b trimmed) at the joint's largest cut within tolerance_mm and
    MAX_SHARE of each line, or None to stop there (as blend.blend_joint)."""
    cut = _cut(a.length_mm, b.length_mm, tolerance_mm, joints, row)
    if cut is None:
        return None
    la, lb = a.curve.length_mm, b.curve.length_mm
    u_a, blend = _trim_and_blend(a, la, cut, b.feed_mm_s, b.line, joints, row)
    u_b = cut / lb
    return (new_piece(a.kind, a.curve, a.u0, u_a, 0.0, u_a * la - a.u0 * la, a.feed_mm_s,
                      a.line, a.corner),
            blend,
            new_piece(b.kind, b.curve, u_b, b.u1, 0.0, b.u1 * lb - u_b * lb, b.feed_mm_s,
                      b.line, b.corner))


def _cut(a_mm: float, b_mm: float, tolerance_mm: float, joints: LineJoints,
         row: int) -> float | None:
    """The largest cut within the tolerance and MAX_SHARE of each line (None: under
    MIN_CUT_MM, a stop)."""
    cut = MAX_SHARE * min(a_mm, b_mm)
    deviation = joints.unit_deviation[row]
    if deviation * cut > tolerance_mm:
        cut = tolerance_mm / deviation * _SAFETY
    return None if cut < MIN_CUT_MM else cut


def _trim_and_blend(a: Piece, la: float, cut: float, feed_mm_s: float, line: int,
                    joints: LineJoints, row: int) -> tuple[float, Piece]:
    """Where a ends once cut (its line's parameter) and the PH blend piece from there."""
    u_a = (a.length_mm - cut + a.u0 * la) / la
    (x0, y0), (x1, y1) = a.curve.p0, a.curve.p1  # type: ignore[attr-defined]
    p0 = complex(x0 + u_a * (x1 - x0), y0 + u_a * (y1 - y0))
    w0, w1, w2 = joints.w_unit[row]
    root = math.sqrt(cut)
    ph = PhQuintic.made(p0, w0 * root, w1 * root, w2 * root)
    return u_a, new_piece(PieceKind.PH, ph, 0.0, 1.0, 0.0, ph.length_mm, feed_mm_s, line)


def applies(a: Piece, b: Piece, joints: LineJoints, row: int) -> bool:
    """Whether blend_lines applies: both pieces whole at the joint (a ends at its line's end,
    b starts at its line's start) and the canonical interpolant is the right one."""
    return (joints.canonical[row] and a.kind == PieceKind.LINE and b.kind == PieceKind.LINE
            and a.u1 == 1.0 and b.u0 == 0.0 and a.u0 < 1.0 and b.u1 > 0.0)


def blend_line_run(pieces: list[Piece], own: list[bool], curves: list[Any], i: int,
                   joints: LineJoints, smooth_rad: float) -> int:
    """build_path's step for lines i, i + 1, ... (BlockCurve) while each one blends onto the
    piece before it (every joint of a G1 program): blend_lines(a, b) for b the whole line, in
    one loop that carries each line over to the next joint as the piece to trim, with its
    parameter and length, and makes its piece once, trimmed at both ends (the last piece
    before the run is trimmed in place when own: made for this path alone). The same pieces
    as blend_lines, the same operations inlined (_cut, _trim_and_blend). Returns the index of
    the first line not taken (i for none): a joint of a line and another curve, a smooth
    joint, a stop."""
    first = pieces[-1]
    if not (first.kind == PieceKind.LINE and first.u1 == 1.0 and first.u0 < 1.0):
        return i
    row_of, canonical, angle = joints.row, joints.canonical, joints.angle_rad
    deviation, w_unit, made, new = joints.unit_deviation, joints.w_unit, PhQuintic.made, new_piece
    line_kind, ph_kind = PieceKind.LINE, PieceKind.PH
    # The line to trim at the next joint: its curve, start parameter, length, and (once made
    # here) its feed and source line.
    curve, u0, a_mm, la = first.curve, first.u0, first.length_mm, first.curve.length_mm
    feed, line = first.feed_mm_s, first.line
    start = i
    while i < len(curves):
        row = row_of.get(i)
        if row is None or not canonical[row] or angle[row] <= smooth_rad:
            break
        tol = curves[i - 1].blend_tolerance_mm
        if not tol:
            break
        bc = curves[i]
        lb = bc.curve.length_mm  # make_piece's length: 1 lb - 0 lb
        cut = MAX_SHARE * min(a_mm, lb)
        dev = deviation[row]
        if dev * cut > tol:
            cut = tol / dev * _SAFETY
        if cut < MIN_CUT_MM:
            break
        u_a = (a_mm - cut + u0 * la) / la
        (x0, y0), (x1, y1) = curve.p0, curve.p1
        w0, w1, w2 = w_unit[row]
        root = math.sqrt(cut)
        ph = made(complex(x0 + u_a * (x1 - x0), y0 + u_a * (y1 - y0)), w0 * root, w1 * root,
                  w2 * root)
        if i > start:
            pieces.append(new(line_kind, curve, u0, u_a, 0.0, u_a * la - u0 * la, feed, line))
        elif own[-1]:
            first.__dict__.update(u1=u_a, length_mm=u_a * la - u0 * la)
        else:
            pieces[-1] = new(first.kind, curve, u0, u_a, 0.0, u_a * la - u0 * la, feed, line,
                             first.corner)
        feed, line = bc.feed_mm_s, bc.line
        pieces.append(new(ph_kind, ph, 0.0, 1.0, 0.0, ph.length_mm, feed, line))
        u0 = cut / lb
        curve, a_mm, la = bc.curve, 1.0 * lb - u0 * lb, lb
        i += 1
    if i > start:
        pieces.append(new(line_kind, curve, u0, 1.0, 0.0, a_mm, feed, line))
        own[-1] = True
        own += [True] * (2 * (i - start))
    return i
