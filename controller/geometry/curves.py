"""Planar curve interface shared by NURBS, lines, arcs and PH quintics, plus line and arc curves."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from controller.numeric import cached_property


@runtime_checkable
class Curve(Protocol):
    """What the corner detector, the PH fitter and the interpolators need from a curve."""

    @property
    def u_start(self) -> float: ...

    @property
    def u_end(self) -> float: ...

    @property
    def length_mm(self) -> float: ...

    def evaluate(self, u: ArrayLike, order: int = 2) -> np.ndarray: ...

    def curvature(self, u: ArrayLike) -> np.ndarray: ...

    def curvature_derivative(self, u: ArrayLike) -> np.ndarray: ...

    def s_of_u(self, u: ArrayLike) -> np.ndarray: ...

    def u_of_s(self, s_mm: ArrayLike, tol_mm: float = 1e-11) -> np.ndarray:
        """Parameter whose arc length is within tol_mm of s_mm (exact curves ignore tol_mm)."""
        ...

    def derivatives_scalar(self, u: float) -> tuple[float, float, float, float]: ...


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def curvature_from_derivatives(d: np.ndarray) -> np.ndarray:
    """Eq. 14, unsigned: |C' x C''| / |C'|^3 from d = [C, C', C'', ...] of shape (>=3, N, 2)."""
    speed2 = np.einsum("ni,ni->n", d[1], d[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(_cross(d[1], d[2])) / speed2**1.5


def curvature_derivative_from_derivatives(d: np.ndarray) -> np.ndarray:
    """d kappa / du from d = [C, C', C'', C'''] (4, N, 2).

    With c = C' x C'' (so c' = C' x C''') and g = |C'|^2 (g' = 2 C'.C''):
    kappa = |c| g^-3/2, kappa' = sign(c) c' g^-3/2 - 3 |c| (C'.C'') g^-5/2.
    """
    c = _cross(d[1], d[2])
    dc = _cross(d[1], d[3])
    g = np.einsum("ni,ni->n", d[1], d[1])
    dot12 = np.einsum("ni,ni->n", d[1], d[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sign(c) * dc / g**1.5 - 3.0 * np.abs(c) * dot12 / g**2.5


def curvature_and_derivative_from_rows(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """curvature_from_derivatives and curvature_derivative_from_derivatives together, from
    rows r = [C, C', C'', C^(3)] of shape (4, 2, N) (x and y rows contiguous): the same
    operations, each product and sum computed once for both (the same numbers)."""
    (x1, y1), (x2, y2), (x3, y3) = r[1], r[2], r[3]
    c = x1 * y2 - y1 * x2
    dc = x1 * y3 - y1 * x3
    g = x1 * x1 + y1 * y1
    dot12 = x1 * x2 + y1 * y2
    abs_c = np.abs(c)
    with np.errstate(divide="ignore", invalid="ignore"):
        g15 = g**1.5
        return abs_c / g15, np.sign(c) * dc / g15 - 3.0 * abs_c * dot12 / g**2.5


def _as_u(u: ArrayLike) -> np.ndarray:
    return np.atleast_1d(np.asarray(u, dtype=float))


class ConstantSpeedCurve:
    """Curves of constant parametric speed on u in [0, 1]: s = u * length, curvature constant."""

    u_start = 0.0
    u_end = 1.0
    length_mm: float

    def curvature(self, u: ArrayLike) -> np.ndarray:
        return np.full(_as_u(u).size, self._curvature)

    def curvature_derivative(self, u: ArrayLike) -> np.ndarray:
        return np.zeros(_as_u(u).size)

    def s_of_u(self, u: ArrayLike) -> np.ndarray:
        return _as_u(u) * self.length_mm

    def u_of_s(self, s_mm: ArrayLike, tol_mm: float = 1e-11) -> np.ndarray:
        return _as_u(s_mm) / self.length_mm


@dataclass(frozen=True)
class LineCurve(ConstantSpeedCurve):
    """Straight segment p0 -> p1 with u in [0, 1] (arc length is exactly u * length)."""

    p0: tuple[float, float]
    p1: tuple[float, float]
    _curvature = 0.0

    @cached_property
    def length_mm(self) -> float:
        # Kept: a G1 program's lines are asked for it at every stage (cut, blend, sampling).
        return math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1])

    def evaluate(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        uu = _as_u(u)
        p0, d = np.asarray(self.p0, float), np.subtract(self.p1, self.p0)
        out = np.zeros((order + 1, uu.size, 2))
        out[0] = p0 + uu[:, None] * d
        if order >= 1:
            out[1] = d
        return out

    def derivatives_scalar(self, u: float) -> tuple[float, float, float, float]:
        return (self.p1[0] - self.p0[0], self.p1[1] - self.p0[1], 0.0, 0.0)


@dataclass(frozen=True)
class ArcCurve(ConstantSpeedCurve):
    """Circular arc: centre, radius, start angle and signed sweep (ccw > 0); u in [0, 1].

    radius_change (end radius minus start radius) makes it LinuxCNC's spiral: the radius goes
    linearly with the angle, so that an arc whose end point is off its circle (the end-radius
    rule allows up to 0.028 mm) still ends there. Its length and constant curvature are then
    the circle's of the mean radius and of the smaller radius: the speed along u differs from
    the constant by under radius_change / (2 * mean radius)."""

    center: tuple[float, float]
    radius: float
    angle0: float
    sweep: float
    radius_change: float = 0.0

    @property
    def length_mm(self) -> float:
        return abs(self.sweep) * (self.radius + 0.5 * self.radius_change)

    def evaluate(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        uu = _as_u(u)
        theta = self.angle0 + self.sweep * uu
        c, s = np.cos(theta), np.sin(theta)
        out = np.empty((order + 1, uu.size, 2))
        # k-th derivative of (cos, sin)(theta) is sweep^k times a rotation by k * 90 degrees.
        rotations = ((c, s), (-s, c), (-c, -s), (s, -c))
        radius = self.radius + self.radius_change * uu if self.radius_change else self.radius
        for k in range(order + 1):
            scale = radius * self.sweep**k
            rx, ry = rotations[k % 4]
            out[k, :, 0] = (self.center[0] if k == 0 else 0.0) + scale * rx
            out[k, :, 1] = (self.center[1] if k == 0 else 0.0) + scale * ry
            if k and self.radius_change:  # Leibniz: k r' sweep^(k-1) (cos, sin)^(k-1)
                qx, qy = rotations[(k - 1) % 4]
                out[k, :, 0] += k * self.radius_change * self.sweep ** (k - 1) * qx
                out[k, :, 1] += k * self.radius_change * self.sweep ** (k - 1) * qy
        return out

    @property
    def _curvature(self) -> float:
        return 1.0 / min(self.radius, self.radius + self.radius_change)

    def derivatives_scalar(self, u: float) -> tuple[float, float, float, float]:
        if self.radius_change:
            d = self.evaluate(u, 2)[:, 0]
            return (float(d[1, 0]), float(d[1, 1]), float(d[2, 0]), float(d[2, 1]))
        theta = self.angle0 + self.sweep * u
        c, s = math.cos(theta), math.sin(theta)
        r1, r2 = self.radius * self.sweep, self.radius * self.sweep**2
        return (-r1 * s, r1 * c, -r2 * c, -r2 * s)
