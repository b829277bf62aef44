"""Controlled stop along the path: quintic deceleration re-timed over buffered reference points;
and, pre-compensated, the frames that let the lead die away at a standstill."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from controller.servo.precompensation import Precompensator

REST_SPEED_MM_S = 0.05  # the reference is "at rest" below this (5 % of a 1 um pulse per ms)


def stop_distances_mm(v0_mm_s: float, accel_mm_s2: float, period_s: float) -> np.ndarray:
    """Distance travelled at samples k = 1..n of a quintic decel from v0 to 0 (docs/algorithms.md,
    Feed planning).

    Duration 15 v0 / (8 A) gives peak deceleration A; rounding it up to whole samples only
    lowers the peak. The last entry is the full stop distance T v0 / 2 (at rest).
    """
    if v0_mm_s <= 0.0:
        return np.zeros(0)
    n = max(1, math.ceil(15.0 * v0_mm_s / (8.0 * accel_mm_s2) / period_s))
    duration_s = n * period_s
    tau = np.arange(1, n + 1) / n
    coeff = np.array([0.0, 1.0, 2.0, 3.0, 3.0, 3.0, 3.0]) * v0_mm_s * duration_s / 6.0
    k = np.arange(7)
    binom = np.array([math.comb(6, i) for i in k], dtype=float)
    basis = binom * tau[:, None] ** k * (1.0 - tau[:, None]) ** (6 - k)
    return basis @ coeff


def amax_stop_distances_mm(v0_mm_s: float, accel_mm_s2: float, period_s: float) -> np.ndarray:
    """Distance travelled at samples k = 1..n of a stop at constant deceleration A: the
    e-stop's, the fastest the drives allow (v0 / A, half the quintic's 15 v0 / (8 A)); its
    jerk is not limited. The last entry is the full stop distance v0^2 / (2 A)."""
    if v0_mm_s <= 0.0:
        return np.zeros(0)
    stop_s = v0_mm_s / accel_mm_s2
    n = max(1, math.ceil(stop_s / period_s - 1e-9))
    t_s = np.minimum(np.arange(1, n + 1) * period_s, stop_s)
    return v0_mm_s * t_s - 0.5 * accel_mm_s2 * t_s**2


def _rest_index(points_mm: np.ndarray, period_s: float) -> int | None:
    """First row where the original reference has come to rest, if any."""
    speed = np.linalg.norm(np.diff(points_mm, axis=0), axis=1) / period_s
    slow = np.nonzero(speed < REST_SPEED_MM_S)[0]
    return int(slow[0]) if slow.size else None


def _direction(points_mm: np.ndarray) -> np.ndarray:
    """Unit direction of the last non-zero segment of a polyline."""
    seg = np.diff(points_mm, axis=0)
    length = np.linalg.norm(seg, axis=1)
    moving = np.nonzero(length > 1e-12)[0]
    if not moving.size:
        return np.zeros(points_mm.shape[1])
    return seg[moving[-1]] / length[moving[-1]]


def _along_polyline(points_mm: np.ndarray, s_mm: np.ndarray,
                    direction: np.ndarray) -> np.ndarray:
    """Positions at arc lengths s along a polyline, extended straight past its end."""
    seg = np.linalg.norm(np.diff(points_mm, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-12])  # np.interp needs increasing abscissae
    pts = points_mm[keep]
    cum = np.concatenate([[0.0], np.cumsum(seg[seg > 1e-12])])
    if s_mm.size and s_mm[-1] > cum[-1]:
        extra = s_mm[-1] - cum[-1] + 1.0
        pts = np.vstack([pts, pts[-1] + direction * extra])
        cum = np.append(cum, cum[-1] + extra)
    return np.column_stack([np.interp(s_mm, cum, pts[:, i]) for i in range(pts.shape[1])])


def stop_along_path(prev_mm: np.ndarray, last_mm: np.ndarray, ahead_mm: np.ndarray,
                    accel_mm_s2: float, period_s: float,
                    distances: Callable[[float, float, float], np.ndarray] = stop_distances_mm
                    ) -> np.ndarray:
    """Rows to append after `last_mm` (already sent, reached from `prev_mm`) to stop on the path.

    ahead_mm are the buffered reference points not yet sent. If the original reference
    comes to rest within them it already stops within the limits: those rows are used as
    they are. Otherwise the decel is re-timed along them, extended straight along the last
    direction when they are too short. Never a position jump: row 0 is one sample after last.
    distances: the deceleration profile (the quintic; amax_stop_distances_mm for an e-stop).
    """
    pts = np.vstack([prev_mm[None, :], last_mm[None, :], ahead_mm.reshape(-1, last_mm.size)])
    rest = _rest_index(pts[1:], period_s)
    v0 = float(np.linalg.norm(last_mm - prev_mm)) / period_s
    s = distances(v0, accel_mm_s2, period_s)
    if rest is not None:
        to_rest_mm = float(np.sum(np.linalg.norm(np.diff(pts[1: rest + 2], axis=0), axis=1)))
        if rest <= s.size or (s.size and to_rest_mm <= s[-1]):
            return pts[2: rest + 2]  # the original reaches rest first: keep its timing
    if s.size == 0:
        return np.zeros((0, last_mm.size))
    return _along_polyline(pts[1:], s, _direction(pts))


def with_lead_settled(precomp: Precompensator, rows: np.ndarray, frames: np.ndarray,
                      last_mm: np.ndarray, line: int) -> tuple[np.ndarray, np.ndarray]:
    """Wanted rows (position, then feed and line columns if any) and their frames, followed
    by the compensator's frames at the standstill (rows repeating the wanted end point, feed 0)
    until its lead has died away: a stream must not end a lead away from the path."""
    tail = precomp.settling_rows()
    if not len(tail):
        return rows, frames
    n, width = len(last_mm), rows.shape[1]
    last = rows[-1] if len(rows) else np.r_[last_mm, 0.0, float(line)][:width]
    still = np.repeat(last[None, :], len(tail), axis=0)
    if width > n:
        still[:, n] = 0.0  # at rest (feed column)
    return np.vstack([rows, still]), np.vstack([frames, tail])
