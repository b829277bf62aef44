"""Homing, host side: each axis's plan from the config, the order of the groups, the final move."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from drivers.errors import HomingError

SEARCH_MARGIN = 0.10  # the switch must be found within the travel length + 10 %


@dataclass(frozen=True)
class HomingPlan:
    """One axis's homing sequence in mm (config axes.*.homing, with the search limit).

    final_mm None means "stop at the point found" (a CiA 402 drive: the host then moves on)."""

    axis: str
    direction: int  # -1 or +1: where the search goes
    search_mm_s: float
    latch_mm_s: float
    accel_mm_s2: float
    home_mm: float  # the point found reads this
    final_mm: float | None
    use_index: bool
    search_limit_mm: float  # switch not found within this distance -> failure


def plan_for(config: MachineConfig, axis: int) -> HomingPlan:
    """The plan of config axis `axis`; HomingError when that axis has no homing section."""
    a = config.axes[axis]
    if a.homing is None:
        raise HomingError(f"{a.name.upper()} axis has no homing sequence configured "
                          f"(axes.{a.name}.homing): its position is absolute", a.name)
    h = a.homing
    lo, hi = a.travel_mm
    return HomingPlan(axis=a.name, direction=h.direction, search_mm_s=h.search_mm_s,
                      latch_mm_s=h.latch_mm_s, accel_mm_s2=h.accel_mm_s2, home_mm=h.home_mm,
                      final_mm=h.final_mm, use_index=h.use_index,
                      search_limit_mm=(hi - lo) * (1.0 + SEARCH_MARGIN))


def homing_groups(config: MachineConfig) -> tuple[tuple[int, ...], ...]:
    """Axes with a homing sequence, grouped by increasing `sequence` (a group homes together):
    the calls to Drive.home() a full homing makes, in order."""
    seqs = sorted({a.homing.sequence for a in config.axes if a.homing is not None})
    return tuple(tuple(i for i, a in enumerate(config.axes)
                       if a.homing is not None and a.homing.sequence == s) for s in seqs)


def axis_names(config: MachineConfig, axes: tuple[int, ...]) -> str:
    return ", ".join(config.axes[i].name.upper() for i in axes)


def trapezoid_counts(distance_counts: int, v_counts_s: float, a_counts_s2: float,
                     period_s: float) -> np.ndarray:
    """Per-sample pulse counts of a rest-to-rest trapezoidal (or triangular) move of
    distance_counts: integers that sum exactly to it."""
    d = abs(int(distance_counts))
    if d == 0:
        return np.zeros(0, dtype=np.int64)
    v = min(v_counts_s, float(np.sqrt(d * a_counts_s2)))  # triangle when too short to cruise
    t_acc = v / a_counts_s2
    t_total = t_acc + d / v
    n = int(np.ceil(t_total / period_s))
    t = np.arange(1, n + 1) * period_s
    s = np.where(t < t_acc, 0.5 * a_counts_s2 * t**2,
                 np.where(t < t_total - t_acc, v * (t - 0.5 * t_acc),
                          d - 0.5 * a_counts_s2 * np.maximum(t_total - t, 0.0) ** 2))
    pos = np.rint(np.minimum(s, d)).astype(np.int64)
    pos[-1] = d
    return np.diff(pos, prepend=0) * (1 if distance_counts > 0 else -1)


def move_frames(from_counts: np.ndarray, to_counts: np.ndarray, v_mm_s: np.ndarray,
                a_mm_s2: np.ndarray, pulse_mm: np.ndarray, period_s: float) -> np.ndarray:
    """(N, n_axes) frames moving every axis from its step counter to its target, each on its
    own trapezoid (speed v, acceleration a), all starting together."""
    moves = [trapezoid_counts(int(t - f), v / p, a / p, period_s)
             for f, t, v, a, p in zip(from_counts, to_counts, v_mm_s, a_mm_s2, pulse_mm,
                                      strict=True)]
    n = max((len(m) for m in moves), default=0)
    frames = np.zeros((n, len(moves)), dtype=np.int64)
    for i, m in enumerate(moves):
        frames[: len(m), i] = m
    return frames
