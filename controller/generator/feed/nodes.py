"""The feed planner's nodes: where the profile passes with zero acceleration, their speed caps,
and the node speeds the quintic transitions can reach both ways."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.generator.feed.check import LimitCurve
from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.generator.feed.time_bound import fb_pass_speed_mm_s

# A quintic transition changes v^2 by 16 A d / 15 over a distance d: an "effective" constant
# acceleration of 8A/15 in the v^2 passes between nodes.
EFFECTIVE_ACCEL_FACTOR = 8.0 / 15.0


def effective_accel(accel: float, shape: TransitionShape = QUINTIC) -> float:
    """The constant acceleration whose v^2 change over a distance a transition matches."""
    return EFFECTIVE_ACCEL_FACTOR * accel if shape.is_quintic else accel / shape.time_factor


STAIR_STEP = 0.03  # relative speed step of the staircase where vlim binds
STAIR_CAP = 0.25  # stair node speed: this many steps below vlim there


@dataclass(eq=False, repr=False)
class Nodes:
    """Planning nodes: the profile passes node k at s[k] with zero acceleration."""

    s: np.ndarray
    cap: np.ndarray  # speed ceiling at the node
    depth: np.ndarray  # per segment (node k to k+1): how often it was split
    flat: np.ndarray  # per segment: no overshoot above the end speeds


def initial_nodes(curve: LimitCurve, v0: float, v1: float, accel: float,
                  shape: TransitionShape = QUINTIC) -> Nodes:
    """The ends, every local minimum of vlim (both ends of a flat bottom, not its inside), and a
    staircase of nodes where vlim binds (see _stair_nodes)."""
    v = curve.vlim_mm_s
    # Runs of equal values: a run is a bottom when both neighbouring runs are higher.
    start = np.flatnonzero(np.concatenate(([True], v[1:] != v[:-1])))
    end = np.append(start[1:] - 1, len(v) - 1)
    # A run at an end is a bottom if its neighbour is higher.
    rv = np.concatenate(([np.inf], v[start], [np.inf]))
    higher_after = rv[1:-1] < rv[2:]
    is_bottom = (rv[1:-1] < rv[:-2]) & higher_after
    bottom = np.flatnonzero(is_bottom)
    # The end of a flat run with a higher one after it (a step up of the feed, F30 then F800
    # then F3300) is a node too: without it the step is inside a segment, whose one shape
    # cannot cruise at the lower feed and then rise again, so it waited at the speed before
    # the steps and crept 70 mm at F30 (139 s instead of 7).
    knee = np.flatnonzero(higher_after & ~is_bottom & (end > start))
    idx = np.concatenate((start[bottom], end[bottom], end[knee]))
    stair, stair_cap = _stair_nodes(curve, v0, v1, effective_accel(accel, shape))
    cap = np.concatenate((v[idx], stair_cap))
    idx = np.concatenate((idx, stair))
    keep = (idx > 0) & (idx < len(v) - 1)
    idx, order = np.unique(idx[keep], return_index=True)
    s = np.concatenate(([0.0], curve.s_mm[idx], curve.s_mm[-1:]))
    cap = np.concatenate(([v0], cap[keep][order], [v1]))
    n = len(s) - 1
    return Nodes(s, cap, np.zeros(n, np.intp), np.zeros(n, bool))


def _stair_nodes(curve: LimitCurve, v0: float, v1: float,
                 mean_accel: float) -> tuple[np.ndarray, np.ndarray]:
    """Where vlim is gentle enough to bind the v^2 passes at the quintics' mean acceleration
    8A/15, the profile must follow it as a staircase (one transition per segment): seed nodes
    where vlim crosses the levels (1+STAIR_STEP)^m, capped STAIR_CAP steps below vlim there."""
    v = curve.vlim_mm_s
    u = fb_pass_speed_mm_s(curve.s_mm, v, mean_accel, v0, v1)
    binding = u >= v * (1.0 - 1e-9)
    level = np.floor(np.log(v) / np.log1p(STAIR_STEP))
    i = 1 + np.flatnonzero(binding[1:] & binding[:-1] & (level[1:] != level[:-1]))
    return i, np.minimum(v[i], v[i - 1]) / (1.0 + STAIR_CAP * STAIR_STEP)
