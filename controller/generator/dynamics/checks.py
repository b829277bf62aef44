"""Figure 4's checks on the servo model's prediction: the stretches whose contour error (eq. 28)
is over the limit, and each stop's largest true distance from the path (its overshoot and the
settling), which the re-planning loop (replan.py) answers by slowing down or braking gentler."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TARGET_FRACTION = 0.95  # re-plan aiming this far under the limit, so rounds converge quickly
LOOKBACK_S = 0.03  # a violation is caused by what the path did up to this long before it
BEFORE_S = 0.05  # a stop's window starts this long before it ...


@dataclass(frozen=True, eq=False)
class Violation:
    """A stretch of samples [k_lo, k_hi] whose |contour error| exceeds the limit."""

    k_lo: int
    k_hi: int
    k_peak: int
    peak_mm: float


@dataclass(frozen=True, eq=False)
class StopError:
    s_mm: float  # where the stop is on the run's path
    k: int  # its sample
    error_mm: float  # largest true distance in its window (the overshoot and its settling)


def find_violations(contour_mm: np.ndarray, limit_mm: float) -> list[Violation]:
    """Contiguous stretches above the limit, each with its peak."""
    over = np.abs(contour_mm) > limit_mm
    if not np.any(over):
        return []
    edges = np.flatnonzero(np.diff(np.r_[0, over.astype(np.int8), 0]))
    out = []
    for lo, hi in zip(edges[::2], edges[1::2] - 1, strict=True):
        k = lo + int(np.argmax(np.abs(contour_mm[lo:hi + 1])))
        out.append(Violation(int(lo), int(hi), int(k), float(abs(contour_mm[k]))))
    return out


def stop_errors(true_mm: np.ndarray, s_mm: np.ndarray, stops_mm: list[float], n_run: int,
                sample_period_s: float) -> list[StopError]:
    """Per stop: the largest true error from BEFORE_S before it to the end of the settling
    window after it (or to the next stop's window)."""
    before = int(round(BEFORE_S / sample_period_s))
    settle = len(true_mm) - n_run
    out = []
    for s_stop in stops_mm:
        k = int(min(np.searchsorted(s_mm, s_stop - 1e-6), n_run - 1))
        window = true_mm[max(0, k - before):min(len(true_mm), k + settle + 1)]
        out.append(StopError(float(s_stop), k, float(window.max()) if window.size else 0.0))
    return out


def near_stops(n: int, stops: list[StopError], sample_period_s: float, settle: int) -> np.ndarray:
    """Mask of the samples inside some stop's window (their error is the stops' business)."""
    before = int(round(BEFORE_S / sample_period_s))
    mask = np.zeros(n, bool)
    for e in stops:
        mask[max(0, e.k - before):min(n, e.k + settle + 1)] = True
    return mask
