"""Time-optimal lower bound on a path: forward-backward pass on v^2 (docs/algorithms.md,
Feed planning)."""

from __future__ import annotations

import numpy as np

from controller.generator.feed.limits import path_feed_limit_mm_s


def fb_pass_speed_mm_s(s_mm: np.ndarray, vlim_mm_s: np.ndarray, accel_mm_s2: float,
                       v_start_mm_s: float = 0.0, v_end_mm_s: float = 0.0) -> np.ndarray:
    """Largest speed profile under vlim with |d(v^2)/ds| <= 2A, pinned at the ends.

    The recurrence v_i^2 = min(lim_i, v_{i-1}^2 + 2A ds_i) is a min-plus scan: with the running
    distance D_i, v_i^2 - 2A D_i = min_{j<=i}(lim_j - 2A D_j), a cumulative minimum (no loop).
    """
    lim = np.asarray(vlim_mm_s, float) ** 2
    lim[0] = min(lim[0], v_start_mm_s ** 2)
    lim[-1] = min(lim[-1], v_end_mm_s ** 2)
    d = 2.0 * accel_mm_s2 * (np.asarray(s_mm, float) - s_mm[0])
    fwd = d + np.minimum.accumulate(lim - d)
    r = d[-1] - d  # distance to the end
    bwd = r + np.minimum.accumulate((fwd - r)[::-1])[::-1]
    return np.sqrt(np.maximum(bwd, 0.0))


def traversal_time_s(s_mm: np.ndarray, v_mm_s: np.ndarray) -> float:
    """T = sum 2 ds / (v_i + v_{i+1}): exact for constant acceleration within each interval."""
    ds = np.diff(np.asarray(s_mm, float))
    vsum = v_mm_s[:-1] + v_mm_s[1:]
    if np.any(vsum <= 0.0):
        raise ValueError("speed is zero over a whole interval: the path cannot be traversed")
    return float(np.sum(2.0 * ds / vsum))


def time_optimal_bound_s(s_mm: np.ndarray, kappa_per_mm: np.ndarray, vmax: float, amax: float,
                         T: float, chord_tol: float) -> float:  # noqa: N803 (T: sample period)
    """Lower bound on the traversal time from rest to rest.

    v_lim = min(Vmax, sqrt(Amax/kappa), V_af) with decoupled tangential |a_t| <= Amax; on the grid
    this is exactly time-optimal, so no real interpolator can be faster. Units: mm, mm/s, mm/s^2, s.
    """
    vlim = path_feed_limit_mm_s(kappa_per_mm, T, chord_tol, amax, vmax)
    return traversal_time_s(s_mm, fb_pass_speed_mm_s(s_mm, vlim, amax))
