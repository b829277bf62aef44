"""G1 line-to-line corners of a long program's windows, every joint of a window at once.

A blend between two lines is symmetric about the joint (the same cut on both sides) and the
PH Hermite construction commutes with similarity, so the blend with cut c is the blend with
cut 1 mm scaled by c about the joint, and its deviation from the two lines is c times that of
the unit blend. One vectorised pass over a window's joints gives each joint's unit blend and
deviation; a joint then takes the largest cut the tolerance and MAX_SHARE of each line allow,
exactly (blend.py bisects for it, one trial at a time, ~0.1 ms per joint: a quarter of the
planning of a G1 program). A single run's plans keep blend.py (bit for bit as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.generator.ph.blend import MAX_BLEND_ANGLE_RAD, MAX_SHARE, MIN_CUT_MM
from controller.geometry.curves import LineCurve
from controller.geometry.path import Piece, PieceKind
from controller.geometry.ph_quintic import TAME_ANGLE_RAD, PhQuintic

_DEVIATION_POINTS = 65  # as blend.deviation_mm measures a trial
_SAFETY = 1.0 - 1e-9  # c D rounds: stay a hair inside the tolerance
_BERNSTEIN5 = np.array([[math.comb(5, k) * x ** k * (1 - x) ** (5 - k) for k in range(6)]
                        for x in np.linspace(0.0, 1.0, _DEVIATION_POINTS)])


@dataclass(frozen=True)
class LineJoints:
    """The joints between consecutive line blocks of a window, by the index of the block after
    the joint: turn angle, deviation of the unit blend (mm per mm of cut), its w coefficients
    (a PH quintic with cut c has w sqrt(c)) and whether the canonical interpolant is the one
    PhQuintic.hermite would choose (both end derivatives tame: turns up to ~160 degrees)."""

    row: dict[int, int]
    angle_rad: np.ndarray
    unit_deviation: np.ndarray
    w_unit: np.ndarray  # (m, 3) complex
    canonical: np.ndarray  # bool


def _unit_tangent(curve: LineCurve) -> complex:
    (x0, y0), (x1, y1) = curve.p0, curve.p1
    t = complex(x1 - x0, y1 - y0)
    return t / abs(t)


def line_joints(curves: list[object]) -> LineJoints:
    """Every joint of two lines in a window's block curves (BlockCurve: .curve)."""
    index = [i for i in range(1, len(curves))
             if isinstance(curves[i - 1].curve, LineCurve)  # type: ignore[attr-defined]
             and isinstance(curves[i].curve, LineCurve)]  # type: ignore[attr-defined]
    t0 = np.array([_unit_tangent(curves[i - 1].curve) for i in index], complex)  # type: ignore[attr-defined]
    t1 = np.array([_unit_tangent(curves[i].curve) for i in index], complex)  # type: ignore[attr-defined]
    turn = t1 * np.conj(t0)
    angle = np.abs(np.angle(turn))
    chord = t0 + t1  # p5 - p0 of the unit blend (zero for a reversal)
    with np.errstate(divide="ignore", invalid="ignore"):
        d0c, d1c = t0 * np.abs(chord) / chord, t1 * np.abs(chord) / chord
    canonical = _tame(d0c) & _tame(d1c) & (angle <= MAX_BLEND_ANGLE_RAD)
    w0, w2 = np.sqrt(d0c), np.sqrt(d1c)
    w1 = -0.75 * (w0 + w2) + 0.25 * np.sqrt(120 - 15 * (w0 * w0 + w2 * w2) + 10 * w0 * w2)
    w = np.column_stack((w0, w1, w2)) * np.sqrt(chord)[:, None]
    w = np.where(canonical[:, None], w, 0.0)
    return LineJoints({i: k for k, i in enumerate(index)}, angle,
                      _deviations(w, -t0, t0, t1), w, canonical)


def _tame(d: np.ndarray) -> np.ndarray:
    """ph_quintic._tame on arrays."""
    return (np.abs(d) >= 0.5) & (np.abs(d) <= 2.0) & (np.abs(np.angle(d)) <= TAME_ANGLE_RAD)


def _deviations(w: np.ndarray, p0: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Largest distance of each unit blend (from p0, the joint at 0) to its two lines."""
    w0, w1, w2 = w[:, 0], w[:, 1], w[:, 2]
    steps = np.column_stack((w0 * w0 / 5, w0 * w1 / 5, (2 * w1 * w1 + w0 * w2) / 15,
                             w1 * w2 / 5, w2 * w2 / 5))
    control = p0[:, None] + np.concatenate((np.zeros((len(w), 1)), np.cumsum(steps, axis=1)),
                                           axis=1)
    pts = np.einsum("mk,pk->mp", control, _BERNSTEIN5)  # (m, points); no BLAS threads
    return np.max(np.minimum(_to_segment(pts, p0, -p0), _to_segment(pts, 0 * t1, t1)), axis=1) \
        if len(w) else np.zeros(0)


def _to_segment(pts: np.ndarray, a: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """Distance of points (m, n) to the segments a + [0, 1] ab (m,), complex coordinates."""
    rel = pts - a[:, None]
    t = np.clip((rel * np.conj(ab)[:, None]).real / np.maximum(np.abs(ab) ** 2, 1e-300)[:, None],
                0.0, 1.0)
    return np.abs(rel - t * ab[:, None])


def blend_lines(a: Piece, b: Piece, tolerance_mm: float, joints: LineJoints,
                row: int) -> tuple[Piece, Piece, Piece] | None:
    """(a trimmed, PH blend, b trimmed) at the joint's largest cut within tolerance_mm and
    MAX_SHARE of each line, or None to stop there (as blend.blend_joint)."""
    cut = MAX_SHARE * min(a.length_mm, b.length_mm)
    deviation = float(joints.unit_deviation[row])
    if deviation * cut > tolerance_mm:
        cut = tolerance_mm / deviation * _SAFETY
    if cut < MIN_CUT_MM:
        return None
    la, lb = a.curve.length_mm, b.curve.length_mm
    u_a = (a.length_mm - cut + a.u0 * la) / la
    u_b = cut / lb
    (x0, y0), (x1, y1) = a.curve.p0, a.curve.p1  # type: ignore[attr-defined]
    p0 = complex(x0 + u_a * (x1 - x0), y0 + u_a * (y1 - y0))
    w0, w1, w2 = joints.w_unit[row] * math.sqrt(cut)
    ph = PhQuintic(p0, complex(w0), complex(w1), complex(w2))
    return (Piece(a.kind, a.curve, a.u0, u_a, 0.0, u_a * la - a.u0 * la, a.feed_mm_s, a.line,
                  a.corner),
            Piece(PieceKind.PH, ph, 0.0, 1.0, 0.0, ph.length_mm, b.feed_mm_s, b.line),
            Piece(b.kind, b.curve, u_b, b.u1, 0.0, b.u1 * lb - u_b * lb, b.feed_mm_s, b.line,
                  b.corner))


def fits(a: Piece, b: Piece, joints: LineJoints, row: int) -> bool:
    """Whether blend_lines applies: both pieces whole at the joint (a ends at its line's end,
    b starts at its line's start) and the canonical interpolant is the right one."""
    return (bool(joints.canonical[row]) and a.kind == PieceKind.LINE and b.kind == PieceKind.LINE
            and a.u1 == 1.0 and b.u0 == 0.0 and a.u0 < 1.0 and b.u1 > 0.0)
