"""Corners inside a NURBS: where its tangent jumps at a knot, and splitting it there (Boehm)."""

from __future__ import annotations

import math

import numpy as np

from controller.geometry.nurbs import Nurbs

# A turn of the tangent across a knot above this is a corner, as at a joint of two G1 blocks
# (construct.SMOOTH_JOINT_RAD): curvature-based detection cannot see it, the curvature on either
# side being finite, so the path would have passed it at full speed with a jump of velocity.
KINK_RAD = math.radians(0.5)
SIDE_STEP = 1e-7  # of the parameter range: where each side's tangent is read


def kink_knots(curve: Nurbs) -> list[float]:
    """Interior knots where the tangent turns by more than KINK_RAD: joints of continuity C0
    (a knot repeated `degree` times, every knot of a polyline) and cusps where repeated control
    points stop the curve. Only those knots can be corners short of a cusp inside a span's
    polynomial, which needs a contrived control polygon and is not looked for: so a curve
    with neither (every airfoil and CAM spline seen) costs one pass over its knots and points,
    not two evaluations (which doubled the interpreter's time on NURBS programs)."""
    knots, p = curve.knots, curve.degree
    inner, count = np.unique(knots[(knots > curve.u_start) & (knots < curve.u_end)],
                             return_counts=True)
    points = curve.control_points
    if not np.any(np.all(points[1:] == points[:-1], axis=1)):
        inner = inner[count >= p]  # without repeated points only C0 joints can turn
    if inner.size == 0:
        return []
    h = SIDE_STEP * (curve.u_end - curve.u_start)
    before = curve.evaluate(inner - h, 1)[1]
    after = curve.evaluate(inner + h, 1)[1]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = np.einsum("ij,ij->i", before, after)
    turn = np.arctan2(np.abs(cross), dot)
    return [float(u) for u in inner[turn > KINK_RAD]]


def still_spans(degree: int, knots: np.ndarray, points: np.ndarray) -> list[tuple[float, float]]:
    """Knot spans [u_k, u_k+1] over which the curve stands still: all degree + 1 control points
    that shape the span are one point (repeated points in a program). The arc-length inverse
    and the PH fit cannot work on a piece of zero length."""
    if not np.any(np.all(points[1:] == points[:-1], axis=1)):
        return []  # no point repeated: every span moves
    out = []
    for k in range(degree, len(knots) - degree - 1):
        if knots[k + 1] > knots[k]:
            shaping = points[k - degree:k + 1]
            if np.all(shaping == shaping[0]):
                out.append((float(knots[k]), float(knots[k + 1])))
    return out


def insert_knot(degree: int, knots: np.ndarray, homogeneous: np.ndarray,
                u: float) -> tuple[np.ndarray, np.ndarray]:
    """Boehm's insertion of u once into (knots, homogeneous points (n, 3)): the same curve."""
    k = int(np.searchsorted(knots, u, side="right")) - 1  # knots[k] <= u < knots[k + 1]
    p = degree
    new = np.empty((homogeneous.shape[0] + 1, homogeneous.shape[1]))
    new[: k - p + 1] = homogeneous[: k - p + 1]
    new[k + 1:] = homogeneous[k:]
    for i in range(k - p + 1, k + 1):
        alpha = (u - knots[i]) / (knots[i + p] - knots[i])
        new[i] = (1.0 - alpha) * homogeneous[i - 1] + alpha * homogeneous[i]
    return np.insert(knots, k + 1, u), new


def split_at(degree: int, knots: np.ndarray, points: np.ndarray, weights: np.ndarray,
             u: float) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """The curve split at an interior parameter u: (knots, points, weights) of the part before
    and of the part after, both clamped; the curve passes through their shared end point."""
    h = np.column_stack((points * weights[:, None], weights))
    while np.count_nonzero(knots == u) < degree:
        knots, h = insert_knot(degree, knots, h, u)
    s = int(np.searchsorted(knots, u, side="left"))  # first of the `degree` copies of u
    left_knots = np.concatenate((knots[:s], np.full(degree + 1, u)))
    right_knots = np.concatenate((np.full(degree + 1, u), knots[s + degree:]))
    left, right = h[:s], h[s - 1:]
    return ((left_knots, left[:, :2] / left[:, 2:], left[:, 2].copy()),
            (right_knots, right[:, :2] / right[:, 2:], right[:, 2].copy()))
