"""The shape of a feed transition: the paper's quintic, or a quintic-edged constant-acceleration
ramp that spends the servo's unused contour budget on a shorter transition (the planner's
transitions, and the ramps of a feed hold and override in the motion loop).

A transition from Vs to Ve over T is v(tau) = Vs + (Ve - Vs) g(tau), s(tau) = T (Vs tau +
(Ve - Vs) G(tau)) with g(0) = 0, g(1) = 1, g' = g'' = 0 at both ends and G(1) = 1/2 (g is
antisymmetric about tau = 1/2, so a transition's length is T (Vs + Ve) / 2 for every shape).

The paper's quintic (ramp_share 1) is g = 10 tau^3 - 15 tau^4 + 6 tau^5: its acceleration
peaks at 15/8 of the mean, so at Amax it takes 15/8 of the time of a constant-acceleration
ramp. With ramp_share r < 1 the acceleration rises along the first half of that quintic's
bell over r/2 of T, holds its peak, and falls the same way over the last r/2 of T: the
acceleration is still continuous and so is the jerk (a C3 position), the peak is
p = 1 / (1 - 7 r / 15) times the mean, and r -> 0 is the trapezoid of Klipper and grbl. The
jerk grows as r falls (peak 16 / (3 sqrt 3) p / r dV / T^2); the dynamics module's contour
check is what bounds it on a machine.

A feed hold's ramp to rest (StopShape) may rise and fall over different shares: a short rise
(the ramp starts at once) and a long fall, so the jerk where the ramp ends, which the servo
follows last and whose residual the tool shows at rest, is small.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

# A ramp holds its peak acceleration for a while: planned at Amax exactly, second differences of
# positions placed to ~1e-8 mm (the arc-length inverse) read up to 2.3e-5 above it. Its peak is
# planned this much below Amax (0.01 % of the transition's time).
PLATEAU_MARGIN = 1e-4
# Along the rise, with u = tau / (r/2) in [0, 1]: the quintic's acceleration bell over its
# first half, scaled to 1 at u = 1: q(u) = u^2 (2 - u)^2; Q = int q, R = int Q.
_Q1 = 8.0 / 15.0  # Q(1)
_R1 = 1.0 / 3.0 - 1.0 / 5.0 + 1.0 / 30.0  # R(1) = 1/6
_PEAK_DQ = 8.0 / (3.0 * np.sqrt(3.0))  # max q'(u) = 4 u (2 - u) (1 - u), at u = 1 - 1/sqrt 3


def _q(u: np.ndarray) -> np.ndarray:
    w = u * (2.0 - u)
    return w * w


def _big_q(u: np.ndarray) -> np.ndarray:
    u3 = u * u * u
    return u3 * (4.0 / 3.0 + u * (-1.0 + u / 5.0))


def _big_r(u: np.ndarray) -> np.ndarray:
    u4 = (u * u) * (u * u)
    return u4 * (1.0 / 3.0 + u * (-1.0 / 5.0 + u / 30.0))


def _speed(tau: np.ndarray, h1: float, h2: float, p: float) -> np.ndarray:
    """g(tau) of a transition whose acceleration rises over h1 and falls over h2 of it, with
    peak p times the mean (TransitionShape: h1 = h2 = ramp_share / 2)."""
    lo = np.minimum(tau, h1) / h1
    hi = np.minimum(1.0 - tau, h2) / h2
    mid = p * (h1 * _Q1 + tau - h1)
    return np.where(tau <= h1, p * h1 * _big_q(lo),
                    np.where(tau >= 1.0 - h2, 1.0 - p * h2 * _big_q(hi), mid))


@dataclass(frozen=True)
class TransitionShape:
    """One transition shape, by the share of the transition its acceleration is not constant."""

    ramp_share: float = 1.0  # 1: the paper's quintic; toward 0: a constant-acceleration ramp

    def __post_init__(self) -> None:
        if not 0.0 < self.ramp_share <= 1.0:
            raise ValueError(f"ramp_share must lie in (0, 1], got {self.ramp_share!r}")

    @property
    def is_quintic(self) -> bool:
        return self.ramp_share == 1.0

    @cached_property
    def peak_factor(self) -> float:
        """Peak over mean acceleration: T = peak_factor |dV| / Amax (15/8 for the quintic)."""
        return 1.0 / (1.0 - 7.0 * self.ramp_share / 15.0)

    @cached_property
    def time_factor(self) -> float:
        """T = time_factor |dV| / Amax: the peak factor with PLATEAU_MARGIN for a ramp."""
        if self.is_quintic:
            return self.peak_factor
        return self.peak_factor / (1.0 - PLATEAU_MARGIN)

    @cached_property
    def jerk_factor(self) -> float:
        """Peak jerk over |dV| / T^2 (10 / sqrt 3 for the quintic)."""
        return self.peak_factor * _PEAK_DQ / (0.5 * self.ramp_share)

    def speed(self, tau: np.ndarray) -> np.ndarray:
        """g(tau), the share of the speed change made by tau."""
        h = 0.5 * self.ramp_share
        return _speed(np.asarray(tau, float), h, h, self.peak_factor)

    def distance(self, tau: np.ndarray) -> np.ndarray:
        """G(tau) = int_0^tau g; G(1) = 1/2."""
        tau = np.asarray(tau, float)
        h, p = 0.5 * self.ramp_share, self.peak_factor
        lo = np.minimum(tau, h) / h
        hi = np.minimum(1.0 - tau, h) / h
        rise = p * h * h * _big_r(lo)
        mid = p * (h * h * _R1 + (h * _Q1 - h) * (tau - h) + 0.5 * (tau * tau - h * h))
        fall = tau - 0.5 + p * h * h * _big_r(hi)
        return np.where(tau <= h, rise, np.where(tau >= 1.0 - h, fall, mid))

    def accel(self, tau: np.ndarray) -> np.ndarray:
        """g'(tau): the acceleration over the mean, (Ve - Vs) / T."""
        tau = np.asarray(tau, float)
        h, p = 0.5 * self.ramp_share, self.peak_factor
        edge = np.minimum(np.minimum(tau, 1.0 - tau), h) / h
        return p * _q(edge)



@dataclass(frozen=True)
class StopShape:
    """A transition whose acceleration rises along the first half of the quintic's bell over
    rise_share of T, holds its peak, and falls the same way over fall_share of T; with
    rise_share = fall_share = r / 2 it is TransitionShape(r). g as there (g(0) = 0,
    g(1) = 1); G(1) = total_share, not 1/2 unless the two shares are equal."""

    rise_share: float
    fall_share: float

    def __post_init__(self) -> None:
        if not (0.0 < self.rise_share and 0.0 < self.fall_share
                and self.rise_share + self.fall_share <= 1.0):
            raise ValueError(f"rise and fall shares must be positive and add up to at most 1, "
                             f"got {self.rise_share!r} and {self.fall_share!r}")

    @cached_property
    def peak_factor(self) -> float:
        """Peak over mean acceleration."""
        return 1.0 / (1.0 - (self.rise_share + self.fall_share) * (1.0 - _Q1))

    @cached_property
    def time_factor(self) -> float:
        """T = time_factor |dV| / Amax (with PLATEAU_MARGIN, as TransitionShape)."""
        return self.peak_factor / (1.0 - PLATEAU_MARGIN)

    def _mid_distance(self, tau: np.ndarray) -> np.ndarray:
        h, p = self.rise_share, self.peak_factor
        return p * (h * h * _R1 + (h * _Q1 - h) * (tau - h) + 0.5 * (tau * tau - h * h))

    @cached_property
    def total_share(self) -> float:
        """G(1): the transition's length to rest is T Vs (1 - G(1))."""
        f = self.fall_share
        edge = float(self._mid_distance(np.asarray(1.0 - f)))
        return edge + f - self.peak_factor * f * f * _R1

    def speed(self, tau: np.ndarray) -> np.ndarray:
        """g(tau), the share of the speed change made by tau."""
        return _speed(np.asarray(tau, float), self.rise_share, self.fall_share,
                      self.peak_factor)

    def distance(self, tau: np.ndarray) -> np.ndarray:
        """G(tau) = int_0^tau g."""
        tau = np.asarray(tau, float)
        h1, h2, p = self.rise_share, self.fall_share, self.peak_factor
        lo = np.minimum(tau, h1) / h1
        hi = np.minimum(1.0 - tau, h2) / h2
        rise = p * h1 * h1 * _big_r(lo)
        fall = self.total_share - (1.0 - tau) + p * h2 * h2 * _big_r(hi)
        return np.where(tau <= h1, rise, np.where(tau >= 1.0 - h2, fall,
                                                   self._mid_distance(tau)))

    def accel(self, tau: np.ndarray) -> np.ndarray:
        """g'(tau): the acceleration over the mean."""
        tau = np.asarray(tau, float)
        lo = np.minimum(tau, self.rise_share) / self.rise_share
        hi = np.minimum(1.0 - tau, self.fall_share) / self.fall_share
        return self.peak_factor * _q(np.minimum(lo, hi))


QUINTIC = TransitionShape(1.0)
