"""Helices and arcs in any of the three planes (G2/G3 in G17, G18, G19) as 3-D curves in machine
axes: exact points, derivatives, arc length, curvature, bounding box and distance."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from controller.blocks import PLANE_AXES, HelixBlock

NEWTON_STEPS = 6  # foot-point iterations: from a nearby start each one squares the error
# The foot point is searched this far each side of the guess (radians of turn) in this many
# steps: a tool lags its reference by far less (at 100 mm/s a lag of 1 mm is 10 ms).
SEARCH_RAD = 1.0
SEARCH_STEPS = 8


@dataclass(frozen=True)
class HelixCurve:
    """C(u) = centre + r(u) (cos, sin)(angle0 + sweep u) in the plane, n0 + rise u along its
    normal, u in [0, 1]; coordinates in machine axes (x, y, z) through PLANE_AXES.

    r(u) = radius + radius_change u: an arc whose end point is off its circle (the end-radius
    rule allows up to 0.028 mm) is LinuxCNC's spiral to that point, as ArcCurve's. Its length
    is then the helix's of the mean radius (the speed along u differs from constant by under
    radius_change / (2 * mean radius)), its curvature the largest of the radii it passes."""

    plane: str
    center: tuple[float, float]
    radius: float
    angle0: float
    sweep: float
    n0: float
    rise: float
    radius_change: float = 0.0

    @classmethod
    def from_block(cls, block: HelixBlock) -> HelixCurve:
        s1, s2, n0 = block.in_plane(block.start)
        c1, c2 = block.center
        return cls(block.plane, (c1, c2), block.radius_mm, math.atan2(s2 - c2, s1 - c1),
                   block.sweep_rad, n0, block.axial_mm, block.radius_change_mm)

    @property
    def length_mm(self) -> float:
        """Unrolled on its cylinder, the helix is a line of legs r * sweep and rise (exact on a
        circle; the mean radius on a spiral)."""
        return math.hypot((self.radius + 0.5 * self.radius_change) * self.sweep, self.rise)

    @property
    def curvature_per_mm(self) -> float:
        """r / (r^2 + c^2) with c the rise per radian: constant on a circle; on a spiral the
        largest over the radii it passes (the most at r = c)."""
        if not self.sweep:
            return 0.0
        c = abs(self.rise / self.sweep)
        r0, r1 = sorted((self.radius, self.radius + self.radius_change))
        radii = [r0, r1] + ([c] if r0 < c < r1 else [])
        return max(r / (r * r + c * c) if r > 0 else 0.0 for r in radii)

    def evaluate(self, u: ArrayLike, order: int = 2) -> np.ndarray:
        """[C, C', ..., C^(order)] at u: shape (order + 1, N, 3), machine axes."""
        uu = np.atleast_1d(np.asarray(u, dtype=float))
        theta = self.angle0 + self.sweep * uu
        c, s = np.cos(theta), np.sin(theta)
        rotations = ((c, s), (-s, c), (-c, -s), (s, -c))  # k-th derivative of (cos, sin)
        a, b, n = PLANE_AXES[self.plane]
        out = np.zeros((order + 1, uu.size, 3))
        change = self.radius_change
        radius = self.radius + change * uu if change else self.radius
        for k in range(order + 1):
            scale = radius * self.sweep**k
            r1, r2 = rotations[k % 4]
            out[k, :, a] = (self.center[0] if k == 0 else 0.0) + scale * r1
            out[k, :, b] = (self.center[1] if k == 0 else 0.0) + scale * r2
            if k and change:  # Leibniz: k r' sweep^(k-1) (cos, sin)^(k-1)
                q1, q2 = rotations[(k - 1) % 4]
                out[k, :, a] += k * change * self.sweep ** (k - 1) * q1
                out[k, :, b] += k * change * self.sweep ** (k - 1) * q2
        out[0, :, n] = self.n0 + self.rise * uu
        if order >= 1:
            out[1, :, n] = self.rise
        return out

    def points(self, u: ArrayLike) -> np.ndarray:
        return self.evaluate(u, 0)[0]

    def distance_mm(self, points: np.ndarray, u_guess: np.ndarray) -> np.ndarray:
        """Each point's distance from the curve near a parameter it is known to be near (the
        sample it was planned from): the nearest of the parameters within SEARCH_RAD of the
        guess, refined by Newton on (C(u) - p) . C'(u) = 0, clamped to [0, 1]."""
        p = np.asarray(points, float)
        u = self._nearest_start(p, np.clip(np.asarray(u_guess, float), 0.0, 1.0))
        for _ in range(NEWTON_STEPS):
            d = self.evaluate(u, 2)
            gap = d[0] - p
            f = np.einsum("ni,ni->n", gap, d[1])
            df = np.einsum("ni,ni->n", d[1], d[1]) + np.einsum("ni,ni->n", gap, d[2])
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(df > 0, f / df, 0.0)
            u = np.clip(u - step, 0.0, 1.0)
        return np.linalg.norm(self.points(u) - p, axis=1)

    def _nearest_start(self, p: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """Of SEARCH_STEPS parameters each side of u0 within SEARCH_RAD of turn, the nearest
        to each point: Newton from there converges to its foot point, not to another one."""
        span = min(1.0, SEARCH_RAD / abs(self.sweep)) if self.sweep else 1.0
        k = np.arange(-SEARCH_STEPS, SEARCH_STEPS + 1) / SEARCH_STEPS
        cand = np.clip(u0[:, None] + span * k[None, :], 0.0, 1.0)  # (n, 2 steps + 1)
        pts = self.points(cand.ravel()).reshape(*cand.shape, 3)
        best = np.argmin(np.sum((pts - p[:, None, :]) ** 2, axis=2), axis=1)
        return cand[np.arange(len(u0)), best]

    def box(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The axis-aligned box (min xyz, max xyz): the circle's extremes where the sweep
        passes them (at the larger radius of a spiral: up to its radius change wide), the
        ends otherwise; the normal axis from its start to its end."""
        ends = self.points([0.0, 1.0])
        lo, hi = ends.min(axis=0), ends.max(axis=0)
        a, b, _ = PLANE_AXES[self.plane]
        start, span = (self.angle0, self.sweep) if self.sweep >= 0 else (
            self.angle0 + self.sweep, -self.sweep)
        for angle, axis, sign in ((0.0, a, 1), (math.pi / 2, b, 1), (math.pi, a, -1),
                                  (1.5 * math.pi, b, -1)):
            if (angle - start) % (2 * math.pi) <= span:
                reach = max(self.radius, self.radius + self.radius_change)
                extreme = self.center[0 if axis == a else 1] + sign * reach
                lo[axis], hi[axis] = min(lo[axis], extreme), max(hi[axis], extreme)
        return (float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]),
                                                            float(hi[2]))
