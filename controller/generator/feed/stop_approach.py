"""The final approach to a stop, made gentler than Amax where the servo would overshoot it.

The quintic braking into rest at Amax leaves the Table II servo loop 51-59 um past the stop
point (its acceleration term c2 a outlasts its velocity lag c1 v near rest): a tool error along
the tangent that eq. 28 cannot see. A stop gets its own braking acceleration, found by the
dynamics module, and the section is planned in two parts (approach_split)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from controller.generator.feed.profile import transition_length_mm
from controller.generator.feed.shape import QUINTIC, TransitionShape

STOP_MATCH_MM = 1e-6  # a section end and a stop position closer than this are the same stop


def stop_accel_at(stops: tuple[tuple[float, float], ...], s_mm: float) -> float | None:
    """The braking acceleration chosen for the stop at s_mm, if any."""
    for s_stop, accel in stops:
        if abs(s_stop - s_mm) <= STOP_MATCH_MM:
            return accel
    return None


def join_speed(s_mm: np.ndarray, vlim_mm_s: np.ndarray, stop_accel_mm_s2: float,
               shape: TransitionShape = QUINTIC) -> float:
    """The approach speed: the lowest vlim over the longest approach braking at the stop's
    acceleration could need, from the grid point before it on (so vlim interpolated anywhere
    in the approach, the split point too, is at least this)."""
    end = float(s_mm[-1])
    reach = float(transition_length_mm(0.0, float(vlim_mm_s.max()), stop_accel_mm_s2, shape))
    first = max(int(np.searchsorted(s_mm, end - reach, side="right")) - 1, 0)
    return float(vlim_mm_s[first:].min())


def model_stop_accel(s_mm: np.ndarray, vlim_mm_s: np.ndarray, accel_mm_s2: float,
                     accel_for: Callable[[float], float],
                     shape: TransitionShape = QUINTIC) -> float:
    """The braking acceleration a model (accel_for: approach speed -> acceleration) gives this
    section's stop; lowered until the approach speed it leads to agrees (three passes)."""
    accel = accel_mm_s2
    for _ in range(3):
        accel = min(accel, accel_for(join_speed(s_mm, vlim_mm_s, accel, shape)))
    return accel


Part = tuple[np.ndarray, np.ndarray, float, float, float]  # s, vlim, accel, v start, v end


def approach_split(s_mm: np.ndarray, vlim_mm_s: np.ndarray, accel_mm_s2: float,
                   stop_accel_mm_s2: float, v_start_mm_s: float,
                   shape: TransitionShape = QUINTIC) -> list[Part]:
    """A section ending at a stop, as two plans: up to the approach at the full acceleration,
    ending at the approach speed v_j, then the approach at the stop's gentler acceleration from
    v_j to rest. v_j is the lowest vlim over the longest approach that could be needed, so it
    holds over the approach, and the approach is as long as braking from v_j takes. A section
    too short for that is planned whole at the stop's acceleration."""
    whole = [(s_mm, vlim_mm_s, stop_accel_mm_s2, v_start_mm_s, 0.0)]
    end = float(s_mm[-1])
    v_join = join_speed(s_mm, vlim_mm_s, stop_accel_mm_s2, shape)
    split = end - float(transition_length_mm(0.0, v_join, stop_accel_mm_s2, shape))
    head = s_mm < split - SPLIT_GAP_MM
    if head.sum() < 2 or v_join <= 0.0:
        return whole
    s_head = np.r_[s_mm[head], split]
    v_head = np.r_[vlim_mm_s[head], np.interp(split, s_mm, vlim_mm_s)]
    tail = s_mm > split + SPLIT_GAP_MM
    s_tail = np.r_[split, s_mm[tail]]
    v_tail = np.r_[np.interp(split, s_mm, vlim_mm_s), vlim_mm_s[tail]]
    return [(s_head, v_head, accel_mm_s2, v_start_mm_s, v_join),
            (s_tail, v_tail, stop_accel_mm_s2, v_join, 0.0)]


SPLIT_GAP_MM = 1e-9  # grid points this close to the split point are dropped (the split is one)
