"""The blend of a G1 corner between two straight lines with a cut of 1 mm on each side.

A blend between two lines is symmetric about the joint and the PH Hermite construction
commutes with similarity: the blend with cut c is this unit blend scaled by c about the
joint, and deviates from the lines c times as much. Vectorised over joints (line_blends.py
blends a window's line joints with it; blend.py aims its first trial with it at a curved one).
"""

from __future__ import annotations

import math

import numpy as np

from controller.geometry.ph_quintic import TAME_ANGLE_RAD

DEVIATION_POINTS = 65  # as blend.deviation_mm measures a trial
_BERNSTEIN5 = np.array([[math.comb(5, k) * x ** k * (1 - x) ** (5 - k) for k in range(6)]
                        for x in np.linspace(0.0, 1.0, DEVIATION_POINTS)])


def unit_blends(t0: np.ndarray, t1: np.ndarray, max_angle_rad: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For unit tangents in (t0) and out (t1) of each joint (complex arrays): the unit blend's
    w coefficients (m, 3) (starting at -t0, the joint at 0; a cut c has w sqrt(c)), its largest
    distance to the two lines (mm per mm of cut) and whether it is the interpolant
    PhQuintic.hermite would choose (its canonical one: both end derivatives tame, turns up to
    ~160 degrees, and at most max_angle_rad). Where not, w and the deviation are 0."""
    chord = t0 + t1  # p5 - p0 (zero for a reversal)
    with np.errstate(divide="ignore", invalid="ignore"):
        d0c, d1c = t0 * np.abs(chord) / chord, t1 * np.abs(chord) / chord
    angle = np.abs(np.angle(t1 * np.conj(t0)))
    canonical = _tame(d0c) & _tame(d1c) & (angle <= max_angle_rad)
    w0, w2 = np.sqrt(d0c), np.sqrt(d1c)
    w1 = -0.75 * (w0 + w2) + 0.25 * np.sqrt(120 - 15 * (w0 * w0 + w2 * w2) + 10 * w0 * w2)
    w = np.column_stack((w0, w1, w2)) * np.sqrt(chord)[:, None]
    w = np.where(canonical[:, None], w, 0.0)
    return w, _deviations(w, -t0, t1), canonical


def _tame(d: np.ndarray) -> np.ndarray:
    """ph_quintic._tame on arrays."""
    return (np.abs(d) >= 0.5) & (np.abs(d) <= 2.0) & (np.abs(np.angle(d)) <= TAME_ANGLE_RAD)


def _deviations(w: np.ndarray, p0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Largest distance of each unit blend (from p0, the joint at 0) to its two lines."""
    if not len(w):
        return np.zeros(0)
    w0, w1, w2 = w[:, 0], w[:, 1], w[:, 2]
    steps = np.column_stack((w0 * w0 / 5, w0 * w1 / 5, (2 * w1 * w1 + w0 * w2) / 15,
                             w1 * w2 / 5, w2 * w2 / 5))
    control = p0[:, None] + np.concatenate((np.zeros((len(w), 1)), np.cumsum(steps, axis=1)),
                                           axis=1)
    pts = np.einsum("mk,pk->mp", control, _BERNSTEIN5)  # (m, points); no BLAS threads
    return np.max(np.minimum(_to_segment(pts, p0, -p0), _to_segment(pts, 0 * t1, t1)), axis=1)


def _to_segment(pts: np.ndarray, a: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """Distance of points (m, n) to the segments a + [0, 1] ab (m,), complex coordinates."""
    rel = pts - a[:, None]
    t = np.clip((rel * np.conj(ab)[:, None]).real / np.maximum(np.abs(ab) ** 2, 1e-300)[:, None],
                0.0, 1.0)
    return np.abs(rel - t * ab[:, None])
