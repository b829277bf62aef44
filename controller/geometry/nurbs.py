"""Planar NURBS: vectorised homogeneous de Boor, derivatives, curvature, arc length."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass
from math import comb, factorial

import numpy as np
from numpy.typing import ArrayLike

from controller.blocks import NurbsBlock
from controller.geometry.arclength import ArcLengthTable
from controller.geometry.curves import (
    curvature_derivative_from_derivatives,
    curvature_from_derivatives,
)
from controller.numeric import cached_property

# Arrays of up to MEMO_POINTS parameters are remembered by value (evaluate, s_of_u): a long
# program's windows ask an interned curve (generator/repeats.py) for the same few points on every
# copy (a piece's ends, its tangent at a joint, its parts' lengths), each call ~20 us of numpy
# against ~1 us for the look-up. At most MEMO_ENTRIES per curve, then the memo starts afresh: an
# airfoil's planning asks 20 (all of them of 4 points or fewer), and a long run interns up to
# 128 curves, so that the memos stay within a megabyte.
MEMO_POINTS = 4
MEMO_ENTRIES = 24


def _derivative_points(knots: np.ndarray, pts: np.ndarray, p: int) -> np.ndarray:
    """Control points of the derivative B-spline (degree p-1, knots[1:-1]); 0 over empty spans."""
    gap = knots[p + 1 : p + pts.shape[0]] - knots[1 : pts.shape[0]]
    scale = np.divide(p, gap, out=np.zeros_like(gap), where=gap > 0)
    return scale[:, None] * np.diff(pts, axis=0)


def _de_boor(knots: np.ndarray, pts: np.ndarray, p: int, span: np.ndarray, u: np.ndarray,
             shift: int) -> np.ndarray:
    """Triangular de Boor scheme on arrays; span indexes the original knots, shift = derivative."""
    k = span - shift  # span in the derivative's knot vector knots[shift:len-shift]
    t = knots[shift : knots.size - shift] if shift else knots
    d = pts[k[:, None] - p + np.arange(p + 1)[None, :]]  # (N, p+1, dim)
    for r in range(1, p + 1):
        for j in range(p, r - 1, -1):
            lo = t[j + k - p]
            hi = t[j + 1 + k - r]
            alpha = ((u - lo) / (hi - lo))[:, None]
            d[:, j] = (1.0 - alpha) * d[:, j - 1] + alpha * d[:, j]
    return d[:, p]


@dataclass(frozen=True, eq=False, repr=False)
class Nurbs:
    """Clamped planar NURBS of any degree; parameter range [knots[p], knots[-p-1]]."""

    degree: int
    knots: np.ndarray  # (n + degree + 1,)
    control_points: np.ndarray  # (n, 2)
    weights: np.ndarray  # (n,)

    def __post_init__(self) -> None:
        n, p = self.control_points.shape[0], self.degree
        if p < 1 or self.knots.size != n + p + 1 or self.weights.size != n:
            raise ValueError(f"inconsistent NURBS: degree {p}, {n} points, {self.knots.size} knots")
        if np.any(np.diff(self.knots) < 0) or np.any(self.weights <= 0):
            raise ValueError("NURBS knots must be non-decreasing and weights positive")

    @classmethod
    def from_block(cls, block: NurbsBlock) -> Nurbs:
        return cls(block.degree, np.asarray(block.knots, float),
                   np.asarray(block.control_points, float), np.asarray(block.weights, float))

    @property
    def u_start(self) -> float:
        return float(self.knots[self.degree])

    @property
    def u_end(self) -> float:
        return float(self.knots[-self.degree - 1])

    @cached_property
    def _polynomial(self) -> bool:
        """All weights 1 (a B-spline): no division by w, whose Horner values are then exact."""
        return bool(np.all(self.weights == 1.0))

    @cached_property
    def _homogeneous(self) -> list[np.ndarray]:
        """Homogeneous control points (w x, w y, w) and those of each derivative curve."""
        pw = np.column_stack((self.control_points * self.weights[:, None], self.weights))
        out = [pw]
        for j in range(1, self.degree + 1):
            out.append(_derivative_points(self.knots[j - 1 : self.knots.size - j + 1],
                                          out[-1], self.degree - j + 1))
        return out

    @cached_property
    def _inner_breaks(self) -> np.ndarray:
        """knots[p+1:n]: the span of u is p plus how many of them are <= u."""
        return np.ascontiguousarray(self.knots[self.degree + 1:self.control_points.shape[0]])

    def _spans(self, u: np.ndarray) -> np.ndarray:
        """The knot span of each u (clamped to p .. n-1): searchsorted(knots, u, "right") - 1
        clamped, counted on the inner breaks alone (no clamp needed)."""
        return self._inner_breaks.searchsorted(u, side="right") + self.degree

    def de_boor_derivatives(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        """[A, A', ..., A^(order)] of the homogeneous curve by de Boor, shape (order+1, N, 3)."""
        uu = np.atleast_1d(np.asarray(u, dtype=float))
        span = self._spans(uu)
        out = np.zeros((order + 1, uu.size, 3))
        for j in range(min(order, self.degree) + 1):
            out[j] = _de_boor(self.knots, self._homogeneous[j], self.degree - j, span, uu, j)
        return out

    @cached_property
    def _taylor_table(self) -> np.ndarray:
        """A^(k)(u_i) / k! at the left end of every non-empty span i, shape (n, p+1, 3).

        Built once by de Boor; evaluation is then a Horner scheme on the span's polynomial,
        several times faster than the triangular scheme on every call (the generator's hot path).
        """
        n, p = self.control_points.shape[0], self.degree
        spans = np.arange(p, n)
        spans = spans[self.knots[spans + 1] > self.knots[spans]]
        left = self.knots[spans]
        table = np.zeros((n, p + 1, 3))
        for j in range(p + 1):
            table[spans, j] = _de_boor(self.knots, self._homogeneous[j], p - j, spans, left,
                                       j) / factorial(j)
        return table

    @cached_property
    def _taylor_columns(self) -> np.ndarray:
        """_taylor_table as ((p+1)*3, n), x and y only, ((p+1)*2, n), when the curve is
        polynomial: gathered by span along the last axis, the coefficients of each row come out
        contiguous, shaped (p+1, dims, N) without a copy."""
        table = self._taylor_table[:, :, :2] if self._polynomial else self._taylor_table
        return np.ascontiguousarray(table.reshape(table.shape[0], -1).T)

    def _homogeneous_rows(self, u: ArrayLike, order: int) -> np.ndarray:
        """[A, A', ..., A^(order)] as (order+1, 3, N): x, y and w rows, each contiguous (x and y
        alone, (order+1, 2, N), when the curve is polynomial: w = 1).

        One pass of Horner's scheme over the span's Taylor coefficients carries the value and
        the derivatives divided by j! (the scheme derivatives_scalar uses): d_j = d_j h + d_(j-1)
        for all j, from the highest down so that each uses the row below from before this step,
        in place (no temporaries), each row starting as a copy of the one below when first
        reached (0 h + d exactly, so no zero-filled array is needed)."""
        uu = np.atleast_1d(np.asarray(u, dtype=float))
        span = self._spans(uu)
        p = self.degree
        dims = 2 if self._polynomial else 3
        coef = self._taylor_columns.take(span, axis=1).reshape(p + 1, dims, uu.size)
        h = uu - self.knots.take(span)
        top = min(order, p)
        out = np.empty((order + 1, dims, uu.size))
        out[p + 1:] = 0.0  # derivatives above the degree (empty unless order > p)
        out[0] = coef[p]
        for k in range(p - 1, -1, -1):
            m = min(top, p - k)  # highest derivative row reached at this step
            if m == p - k:
                out[m] = out[m - 1]
                m -= 1
            for j in range(m, 0, -1):
                row = out[j]
                row *= h
                row += out[j - 1]
            row = out[0]
            row *= h
            row += coef[k]
        for j in range(2, top + 1):
            out[j] *= factorial(j)
        return out

    def homogeneous_derivatives(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        """[A, A', ..., A^(order)] of the homogeneous curve, shape (order+1, N, 3)."""
        a = self._homogeneous_rows(u, order)
        if self._polynomial:
            w = np.zeros((order + 1, 1, a.shape[2]))
            w[0] = 1.0
            a = np.concatenate((a, w), axis=1)
        return a.transpose(0, 2, 1)

    @cached_property
    def _memo(self) -> dict[tuple[int, bytes], np.ndarray]:
        """Results of evaluate (key: order >= 0) and s_of_u (key: -1) on small arrays, by the
        parameters' bytes: the same numbers as a call, copied out so no caller shares them."""
        return {}

    def _remembered(self, kind: int, u: ArrayLike,
                    compute: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        uu = np.atleast_1d(np.asarray(u, dtype=float))
        if uu.size > MEMO_POINTS:
            return compute(uu)
        memo, key = self._memo, (kind, uu.tobytes())
        found = memo.get(key)
        if found is None:
            if len(memo) >= MEMO_ENTRIES:
                memo.clear()
            found = memo[key] = compute(uu)
        return found.copy()

    def evaluate(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        """[C, C', ..., C^(order)] of shape (order+1, N, 2), by Leibniz on A = w C (A itself
        when the curve is polynomial); small arrays remembered (_memo)."""
        return self._remembered(order, u, lambda uu: self._evaluate(uu, order))

    def _evaluate(self, u: np.ndarray, order: int) -> np.ndarray:
        return self.evaluate_rows(u, order).transpose(0, 2, 1)

    def evaluate_rows(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        """evaluate as (order+1, 2, N): each derivative's x and y rows contiguous (the array
        evaluate returns a view of), for arithmetic on x and y without strided reads."""
        a = self._homogeneous_rows(u, order)
        if self._polynomial:  # w = 1, w' = w'' = ... = 0: C^(k) = A^(k)
            return a
        w = a[:, 2]
        inv_w = 1.0 / w[0]
        c = np.empty((order + 1, 2, a.shape[2]))
        for k in range(order + 1):
            acc = a[k, :2].copy()
            for i in range(1, k + 1):
                acc -= (comb(k, i) * w[i]) * c[k - i]
            acc *= inv_w
            c[k] = acc
        return c

    def curvature(self, u: ArrayLike) -> np.ndarray:
        """Eq. 14 (unsigned), 1/mm."""
        return curvature_from_derivatives(self.evaluate(u, 2))

    def curvature_derivative(self, u: ArrayLike) -> np.ndarray:
        """d kappa / du from C', C'', C'''."""
        return curvature_derivative_from_derivatives(self.evaluate(u, 3))

    def speed(self, u: np.ndarray) -> np.ndarray:
        """|C'(u)|, never remembered: the arc-length tables and their Newton steps ask it at
        points that seldom come back."""
        d1 = self.evaluate_rows(u, 1)[1]
        return np.hypot(d1[0], d1[1])

    @cached_property
    def arc_length_table(self) -> ArcLengthTable:
        inner = self.knots[self.degree : self.knots.size - self.degree]
        return ArcLengthTable.build(self.speed, inner, derivs=lambda u: self.evaluate_rows(u, 2))

    @property
    def length_mm(self) -> float:
        return self.arc_length_table.total_length_mm

    def s_of_u(self, u: ArrayLike) -> np.ndarray:
        return self._remembered(-1, u, self.arc_length_table.s_of_u)

    def u_of_s(self, s_mm: ArrayLike, tol_mm: float = 1e-11) -> np.ndarray:
        return self.arc_length_table.u_of_s(s_mm, tol_mm)

    @cached_property
    def _power_form(self) -> tuple[list[float], list[list[list[float]]]]:
        """Per-span Taylor coefficients A^(k)(u_i)/k! of the homogeneous curve, as Python floats."""
        p, n = self.degree, self.control_points.shape[0]
        left = self.knots[p:n]  # span i starts at knots[i]; an empty one is never looked up
        return left.tolist(), self._taylor_table[p:n, ::-1].tolist()  # highest power first

    def _derivatives_scalar(self, u: float, order: int) -> list[list[float]]:
        """[C, C', ..., C^(order)] at one u as [x, y] pairs, without numpy: Horner on the span's
        power form carrying the homogeneous derivatives, then Leibniz on A = w C (w = 1, x and y
        alone, when the curve is polynomial)."""
        breaks, coeffs = self._power_form
        i = min(max(bisect.bisect_right(breaks, u) - 1, 0), len(breaks) - 1)
        h = u - breaks[i]
        dims = 2 if self._polynomial else 3
        a = [[0.0, 0.0, 0.0] for _ in range(order + 1)]
        for c in coeffs[i]:  # highest power first
            for j in range(dims):
                for k in range(order, 0, -1):
                    a[k][j] = a[k][j] * h + k * a[k - 1][j]
                a[0][j] = a[0][j] * h + c[j]
        if dims == 2:  # w = 1: no quotient rule
            return [row[:2] for row in a]
        w = [row[2] for row in a]
        d: list[list[float]] = []
        for k in range(order + 1):
            num = [a[k][0], a[k][1]]
            for m in range(1, k + 1):
                for j in range(2):
                    num[j] -= comb(k, m) * w[m] * d[k - m][j]
            d.append([num[0] / w[0], num[1] / w[0]])
        return d

    def derivatives_scalar(self, u: float) -> tuple[float, float, float, float]:
        """(x', y', x'', y'') at one u without numpy."""
        _, d1, d2 = self._derivatives_scalar(u, 2)
        return d1[0], d1[1], d2[0], d2[1]

    def curvature_derivative_scalar(self, u: float) -> float:
        """d kappa / du at one u without numpy (as curves.curvature_derivative_from_derivatives)."""
        _, d1, d2, d3 = self._derivatives_scalar(u, 3)
        cross = d1[0] * d2[1] - d1[1] * d2[0]
        dcross = d1[0] * d3[1] - d1[1] * d3[0]
        g = d1[0] * d1[0] + d1[1] * d1[1]
        if g == 0.0:
            return float(self.curvature_derivative(u)[0])  # the vectorised form's handling
        dot12 = d1[0] * d2[0] + d1[1] * d2[1]
        return math.copysign(1.0, cross) * dcross / g**1.5 * (cross != 0.0) \
            - 3.0 * abs(cross) * dot12 / g**2.5

