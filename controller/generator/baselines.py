"""Baseline interpolators without look-ahead: adaptive feed (Yeh & Hsu), curvature feed (Zhiming).

Both command a feed computed from the curvature at the current parameter, with no acceleration
limit (that is what the paper compares against), and step along each curve with the
second-order Taylor interpolator (eq. 5). They start at full feed and stop dead at the end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from controller.generator.feed.limits import chord_error_feed_mm_s, curvature_feed_mm_s
from controller.generator.ph.construct import BlockCurve
from controller.geometry.taylor import taylor_step

FORMULA_FEEDS = ("adaptive", "curvature")
MAX_SAMPLES = 10_000_000  # a guard: a feed of zero would otherwise never reach the end


@dataclass(frozen=True, eq=False, repr=False)
class FormulaSamples:
    xy_mm: np.ndarray
    v_mm_s: np.ndarray
    line: np.ndarray


def _feed(kind: str, kappa: float, cap: float, config: MachineConfig) -> float:
    ip = config.interpolator
    if kind == "adaptive":
        return float(chord_error_feed_mm_s(kappa, config.sample_period_s, ip.chord_tolerance_mm,
                                           cap))
    return float(curvature_feed_mm_s(kappa, ip.reference_curvature_per_mm, cap))


def _curvature(d: tuple[float, float, float, float]) -> float:
    dx, dy, ddx, ddy = d
    speed2 = dx * dx + dy * dy
    return abs(dx * ddy - dy * ddx) / (speed2 * math.sqrt(speed2)) if speed2 > 0 else 0.0


def _walk(bc: BlockCurve, kind: str, config: MachineConfig) -> tuple[list[float], list[float]]:
    """Parameters u_1..u_n along one curve (the last one is its end) and the feeds used."""
    curve, T = bc.curve, config.sample_period_s  # noqa: N806
    cap = min(bc.feed_mm_s, config.interpolator.max_feed_mm_s)
    u, us, feeds = curve.u_start, [], []
    while u < curve.u_end and len(us) < MAX_SAMPLES:
        v = _feed(kind, _curvature(curve.derivatives_scalar(u)), cap, config)
        u = min(taylor_step(curve, u, v, 0.0, T), curve.u_end)
        us.append(u)
        feeds.append(v)
    return us, feeds


def plan_formula_run(curves: list[BlockCurve], config: MachineConfig, kind: str) -> FormulaSamples:
    """Reference points of one run under a formula feed (no look-ahead, no dynamics)."""
    xy_parts, v_parts, line_parts = [], [], []
    for bc in curves:
        us, feeds = _walk(bc, kind, config)
        xy_parts.append(bc.curve.evaluate(np.array(us), 0)[0])
        v_parts.append(np.array(feeds))
        line_parts.append(np.full(len(us), bc.line, np.int32))
    return FormulaSamples(np.vstack(xy_parts), np.concatenate(v_parts),
                          np.concatenate(line_parts))
