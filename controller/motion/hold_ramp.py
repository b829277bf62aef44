"""The feed hold's ramp: the path speed brought from where it is to rest along the planned rows
with a stop shape at Amax (the rise of interpolator.ramp_share, a long fall), placed by arc
length."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.transition_shape import StopShape, TransitionShape

ACCEL_SHARE = 0.98  # the ramp's peak deceleration: this share of Amax (placing rows by arc
#                     length on a polyline of the rows reads a little above it at curves)
# The ramp's deceleration falls over this share of it (at most; never over less than it rises):
# the servo's residual of a ramp that ends with a small jerk is gone sooner. Measured on the
# shipped config (pre-compensated, ramp_share 0.1, bench/hold_feed.py): the tool within 2 um
# of rest 44 ms median after the request with 0.8, 46 ms with 0.7, 49.5 ms with the rise's
# own 0.05. The ramp itself is longer (40 against 26 ms from 58 mm/s), its last part slow.
HOLD_FALL_SHARE = 0.8
REST_STEP_MM = 5e-5  # a row closer than this to the next is the plan at rest (0.05 mm/s at 1 ms)


@dataclass
class PathRamp:
    """A ramp given sample by sample: the reference rows advanced at each output sample (the
    time scale of that sample), then rate1. Plays the part of retime.Ramp in the Retimer."""

    steps: np.ndarray
    rate1: float = 0.0
    k: int = 0  # samples of it done

    @property
    def rate0(self) -> float:
        return float(self.steps[0]) if len(self.steps) else self.rate1

    @property
    def n(self) -> int:
        return len(self.steps)

    @property
    def span(self) -> float:
        return float(self.n)

    def rates(self, count: int) -> np.ndarray:
        """The next `count` rates (rate1 once the ramp is over); does not advance."""
        ahead = self.steps[self.k : self.k + count]
        return np.concatenate([ahead, np.full(count - len(ahead), self.rate1)])

    @property
    def done(self) -> bool:
        return self.k >= self.n


def hold_shape(ramp_share: float) -> TransitionShape | StopShape:
    """A hold's stop shape: the rise of the planner's transitions (half of ramp_share), the
    fall over HOLD_FALL_SHARE; the planner's shape itself where that is no longer a fall
    (ramp_share 1: the paper's quintic)."""
    rise = 0.5 * ramp_share
    fall = min(HOLD_FALL_SHARE, 1.0 - rise)
    return StopShape(rise, fall) if fall > rise else TransitionShape(ramp_share)


def hold_distances_mm(
    v0_mm_s: float,
    accel_mm_s2: float,
    period_s: float,
    shape: TransitionShape | StopShape,
    stretch: float = 1.0,
) -> np.ndarray:
    """Distance travelled at samples k = 1..n of the shape's transition from v0 to rest with
    its peak at ACCEL_SHARE x Amax (stretch > 1: that much longer); the last is the whole."""
    if v0_mm_s <= 0.0:
        return np.zeros(1)
    ramp_s = stretch * shape.time_factor * v0_mm_s / (ACCEL_SHARE * accel_mm_s2)
    n = max(1, math.ceil(ramp_s / period_s - 1e-9))  # whole samples: the peak only lowers
    tau = np.arange(1, n + 1) / n
    return v0_mm_s * n * period_s * (tau - shape.distance(tau))


def hold_steps(
    pos_mm: np.ndarray, tau0: float, distances_mm: np.ndarray, cap: float = 1.0
) -> np.ndarray:
    """Rows advanced at each sample so that the path, from fractional row tau0, covers
    distances_mm (by arc length along the rows), never more than `cap` rows a sample: never
    faster than the plan (times the override now) at the same point, where its normal
    acceleration and contour error were checked (a hold in a deceleration into a corner
    follows the plan's deceleration until its own is the slower). Where the rows themselves
    come to rest first (a pause, the program end, a stop the plan makes) the hold follows them
    there at their own timing, as a stop along the path does (motion/stopping.py)."""
    first = int(math.floor(tau0))
    tau0 -= first
    ahead = 4 * len(distances_mm) + 8  # rows enough unless the plan slows right down
    cum, rest = _rows_to_rest(pos_mm[first : first + ahead + 1])
    s0 = float(np.interp(tau0, np.arange(rest + 1), cum[: rest + 1]))
    if (
        s0 + distances_mm[-1] >= cum[rest]
        and rest == len(cum) - 1
        and first + len(cum) < len(pos_mm)
    ):  # the window ends first: all the rows
        cum, rest = _rows_to_rest(pos_mm[first:])
    idx = np.arange(rest + 1, dtype=float)
    if s0 + distances_mm[-1] >= cum[rest] or rest <= tau0:  # the plan comes to rest first
        tau = np.minimum(tau0 + np.arange(1, math.ceil(rest - tau0 - 1e-12) + 1), rest)
        return np.diff(np.concatenate([[tau0], tau])) if len(tau) else np.zeros(1)
    tau = np.interp(s0 + distances_mm, cum[: rest + 1], idx)
    steps = np.diff(np.concatenate([[tau0], tau]))
    if steps.max() <= cap:
        return steps
    return _capped(cum[: rest + 1], idx, tau0, np.diff(distances_mm, prepend=0.0), cap)


def _capped(
    cum: np.ndarray, idx: np.ndarray, tau0: float, step_mm: np.ndarray, cap: float
) -> np.ndarray:
    """Each sample the shape's own distance or `cap` rows, whichever is the shorter, from
    where the last one ended. A loop over the ramp's samples (tens), each depending on the
    one before; done once a hold."""
    out = np.empty(len(step_mm))
    tau, s = tau0, float(np.interp(tau0, idx, cum))
    for k, ds in enumerate(step_mm):
        nxt = min(float(np.interp(s + ds, cum, idx)), tau + cap)
        out[k], tau = nxt - tau, nxt
        s = float(np.interp(tau, idx, cum))
    return out


def _rows_to_rest(pos_mm: np.ndarray) -> tuple[np.ndarray, int]:
    """The rows' cumulative arc length, and the first row where they come to rest (the last
    row when they do not)."""
    seg = np.linalg.norm(np.diff(pos_mm, axis=0), axis=1)
    still = np.flatnonzero(seg < REST_STEP_MM)
    rest = int(still[0]) if still.size else len(pos_mm) - 1
    return np.concatenate([[0.0], np.cumsum(seg)]), rest
