"""Quintic Bernstein feed transitions and cruises (paper eqs. 25-26), evaluated in closed form."""

from __future__ import annotations

from collections.abc import Iterable
from functools import cached_property
from typing import NamedTuple

import numpy as np

from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.numeric import clamp

# Peak |a| of the quintic transition is (15/8)|dV|/T (at tau = 1/2); T is chosen so it equals Amax.
PEAK_ACCEL_FACTOR = 15.0 / 8.0


def transition_duration_s(v_start_mm_s: np.ndarray | float, v_end_mm_s: np.ndarray | float,
                          accel_mm_s2: float, shape: TransitionShape = QUINTIC) -> np.ndarray:
    """Duration T = 15|Ve-Vs|/(8 Amax): the fastest quintic transition whose peak |a| is Amax
    (another shape: its peak factor for 15/8)."""
    dv = np.abs(np.asarray(v_end_mm_s, float) - np.asarray(v_start_mm_s, float))
    if shape.is_quintic:
        return PEAK_ACCEL_FACTOR * dv / accel_mm_s2
    return shape.time_factor * dv / accel_mm_s2


def transition_length_mm(v_start_mm_s: np.ndarray | float, v_end_mm_s: np.ndarray | float,
                         accel_mm_s2: float, shape: TransitionShape = QUINTIC) -> np.ndarray:
    """Distance of that transition, T(Vs+Ve)/2 = 15|Ve^2-Vs^2|/(16 Amax)."""
    vs, ve = np.asarray(v_start_mm_s, float), np.asarray(v_end_mm_s, float)
    if shape.is_quintic:
        return 15.0 * np.abs(ve * ve - vs * vs) / (16.0 * accel_mm_s2)
    return shape.time_factor * np.abs(ve * ve - vs * vs) / (2.0 * accel_mm_s2)


def shaped_distance(tau: np.ndarray, duration_s: np.ndarray, vs: np.ndarray, ve: np.ndarray,
                    shape: TransitionShape) -> np.ndarray:
    """quintic_distance for any shape: T (vs tau + (ve - vs) G(tau))."""
    if shape.is_quintic:
        return quintic_distance(tau, duration_s, vs, ve)
    return duration_s * (vs * tau + (ve - vs) * shape.distance(tau))


def shaped_speed(tau: np.ndarray, vs: np.ndarray, ve: np.ndarray,
                 shape: TransitionShape) -> np.ndarray:
    """quintic_speed for any shape: vs + (ve - vs) g(tau)."""
    if shape.is_quintic:
        return quintic_speed(tau, vs, ve)
    return vs + (ve - vs) * shape.speed(tau)


def bernstein6_distance(tau: np.ndarray, duration_s: np.ndarray, vs: np.ndarray,
                        ve: np.ndarray) -> np.ndarray:
    """Distance travelled after tau*T: (T/6) sum F_k b_k^6(tau), F_k = [0,Vs,2Vs,3Vs,3Vs+Ve,..]."""
    return bernstein6_sum(bernstein6_weights(tau), duration_s, vs, ve)


def quintic_distance(tau: np.ndarray, duration_s: np.ndarray, vs: np.ndarray,
                     ve: np.ndarray) -> np.ndarray:
    """bernstein6_distance in power form, T (vs tau + (ve - vs)(5/2 tau^4 - 3 tau^5 + tau^6)):
    the integral of quintic_speed. A third of the operations, for the planner's checks; it
    agrees with the Bernstein form to round-off (tests/generator/test_feed_profile.py)."""
    t2 = tau * tau
    t4 = t2 * t2
    return duration_s * (vs * tau + (ve - vs) * (t4 * (2.5 + tau * (tau - 3.0))))


def bernstein6_weights(tau: np.ndarray) -> tuple[np.ndarray, ...]:
    """b_1^6 .. b_6^6 at tau (b_0^6 has F_0 = 0, so it is omitted); reusable for fixed tau."""
    u = 1.0 - tau
    t2, u2 = tau * tau, u * u
    t3, u3 = t2 * tau, u2 * u
    return (6.0 * u3 * u2 * tau, 15.0 * u2 * u2 * t2, 20.0 * u3 * t3, 15.0 * u2 * t2 * t2,
            6.0 * u * t3 * t2, t3 * t3)


def bernstein6_sum(weights: tuple[np.ndarray, ...], duration_s: np.ndarray, vs: np.ndarray,
                   ve: np.ndarray) -> np.ndarray:
    """bernstein6_distance from precomputed bernstein6_weights."""
    w1, w2, w3, w4, w5, w6 = weights
    acc = w1 * vs
    acc += w2 * (2.0 * vs)
    acc += w3 * (3.0 * vs)
    acc += w4 * (3.0 * vs + ve)
    acc += w5 * (3.0 * vs + 2.0 * ve)
    acc += w6 * (3.0 * vs + 3.0 * ve)
    return duration_s / 6.0 * acc


def quintic_speed(tau: np.ndarray, vs: np.ndarray, ve: np.ndarray) -> np.ndarray:
    """V(tau) = sum V_k b_k^5 with V0..2 = Vs, V3..5 = Ve, i.e. Vs + dV (10t^3 - 15t^4 + 6t^5)."""
    smooth = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    return vs + (ve - vs) * smooth


def quintic_accel(tau: np.ndarray, duration_s: np.ndarray, vs: np.ndarray,
                  ve: np.ndarray) -> np.ndarray:
    """a = (Ve-Vs)/T * 30 tau^2 (1-tau)^2; zero (with the jerk) at both ends."""
    safe_t = np.where(duration_s > 0.0, duration_s, 1.0)
    w = tau * (1.0 - tau)
    return np.where(duration_s > 0.0, (ve - vs) / safe_t * 30.0 * w * w, 0.0)


class FeedPhase(NamedTuple):
    """One phase of a feed profile: a quintic transition, or a cruise when the speeds are equal
    (a row of FeedProfile, as a tuple for code that walks the phases one by one)."""

    t0_s: float
    duration_s: float
    s0_mm: float
    v_start_mm_s: float
    v_end_mm_s: float

    @property
    def length_mm(self) -> float:
        return 0.5 * self.duration_s * (self.v_start_mm_s + self.v_end_mm_s)


class FeedProfile:
    """A chain of feed phases, contiguous in time and arc length, C2 at the joints.

    Held as rows (t0, duration, s0, vs, ve), what evaluation works on: a long program's window
    has tens of thousands of phases, and a Python tuple for each was a twentieth of planning a
    G1 walk. The tuples (phases) are made only when asked for."""

    def __init__(self, phases: Iterable[FeedPhase] = (),
                 shape: TransitionShape = QUINTIC) -> None:
        self._arr = np.array(list(phases), dtype=float).reshape(-1, 5)
        self.shape = shape

    @classmethod
    def from_rows(cls, rows: np.ndarray, shape: TransitionShape = QUINTIC) -> FeedProfile:
        """A profile of (n, 5) rows (t0, duration, s0, vs, ve), kept as they are."""
        profile = cls.__new__(cls)
        profile._arr = np.asarray(rows, float).reshape(-1, 5)
        profile.shape = shape
        return profile

    @classmethod
    def from_arrays(cls, duration_s: np.ndarray, s0_mm: np.ndarray, v_start_mm_s: np.ndarray,
                    v_end_mm_s: np.ndarray, t0_s: float = 0.0,
                    shape: TransitionShape = QUINTIC) -> FeedProfile:
        """Build from per-phase arrays; start times are the running sum of durations."""
        dur = np.asarray(duration_s, float)
        t0 = t0_s + np.concatenate(([0.0], np.cumsum(dur)[:-1])) if dur.size else dur
        return cls.from_rows(np.column_stack((t0, dur, s0_mm, v_start_mm_s, v_end_mm_s)), shape)

    @cached_property
    def phases(self) -> tuple[FeedPhase, ...]:
        return tuple(map(FeedPhase._make, self._arr.tolist()))

    @property
    def rows(self) -> np.ndarray:
        """The phases as (n, 5) rows (t0, duration, s0, vs, ve); not to be written to."""
        return self._arr

    def __len__(self) -> int:
        return len(self._arr)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, FeedProfile):
            return NotImplemented
        return self.shape == other.shape and bool(np.array_equal(self._arr, other._arr))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"FeedProfile({len(self._arr)} phases, {self.duration_s:.6g} s)"

    @property
    def t0_s(self) -> float:
        return float(self._arr[0, 0]) if len(self._arr) else 0.0

    @property
    def duration_s(self) -> float:
        if not len(self._arr):
            return 0.0
        return float(self._arr[-1, 0] + self._arr[-1, 1] - self._arr[0, 0])

    @property
    def length_mm(self) -> float:
        if not len(self._arr):
            return 0.0
        last = self._arr[-1]
        return float(last[2] + 0.5 * last[1] * (last[3] + last[4]) - self._arr[0, 2])

    def evaluate(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(s_mm, v_mm_s, a_mm_s2) at the given times; times outside the profile are clamped."""
        t = np.asarray(t_s, dtype=float)
        if not len(self._arr):
            z = np.zeros_like(t)
            return z, z.copy(), z.copy()
        arr = self._arr
        t = clamp(t, arr[0, 0], arr[-1, 0] + arr[-1, 1])
        k = clamp(np.searchsorted(arr[:, 0], t, side="right") - 1, 0, len(arr) - 1)
        t0, dur, s0, vs, ve = (arr[k, j] for j in range(5))
        # Zero-length phases never get selected unless at the very end; guard the division.
        tau = clamp((t - t0) / np.where(dur > 0.0, dur, 1.0), 0.0, 1.0)
        if self.shape.is_quintic:
            s = s0 + bernstein6_distance(tau, dur, vs, ve)
            return s, quintic_speed(tau, vs, ve), quintic_accel(tau, dur, vs, ve)
        shape = self.shape
        safe_t = np.where(dur > 0.0, dur, 1.0)
        a = np.where(dur > 0.0, (ve - vs) / safe_t * shape.accel(tau), 0.0)
        return s0 + shaped_distance(tau, dur, vs, ve, shape), shaped_speed(tau, vs, ve, shape), a
