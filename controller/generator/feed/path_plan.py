"""Module 3 of the generator: the feed-limit curve along a path and its quintic feed plan."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from controller.generator.feed.grid import PieceSamples, grid_step_mm, limit_samples
from controller.generator.feed.limits import chord_error_feed_mm_s, corner_feed_mm_s
from controller.generator.feed.planner import PlanResult, plan_feed
from controller.generator.feed.profile import FeedProfile
from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.generator.feed.stop_approach import (
    STOP_MATCH_MM,
    approach_split,
    model_stop_accel,
    stop_accel_at,
)
from controller.geometry.path import Path
from controller.numeric import sorted_unique


class LimitPolicy(StrEnum):
    CONTINUOUS = "continuous"  # ph-lookahead: curvature feed everywhere, contour-derived
    CORNER_PLATEAU = "corner-plateau"  # Tsai 2008: V_sp = min(V_af, V_cf) held over each zone


@dataclass(frozen=True, eq=False)
class Reduction:
    """Dynamics module's verdict: scale the centripetal budget by factor over [s_lo, s_hi]."""

    s_lo_mm: float
    s_hi_mm: float
    factor: float


@dataclass(frozen=True, eq=False)
class FeedInput:
    """Everything module 3 needs besides the path (mm, s)."""

    max_feed_mm_s: float
    max_accel_mm_s2: float
    sample_period_s: float
    chord_tolerance_mm: float
    kappa_bar_per_mm: float
    centripetal_accel_mm_s2: float  # normal-acceleration budget (contour-error derived)
    policy: LimitPolicy = LimitPolicy.CONTINUOUS
    reductions: tuple[Reduction, ...] = field(default=())
    # (s of a stop, braking acceleration into it), from the dynamics module
    # (feed/stop_approach.py)
    stop_accels: tuple[tuple[float, float], ...] = field(default=())
    # the dynamics module's first guess for stops without one: approach speed -> acceleration
    stop_accel_for: Callable[[float], float] | None = None
    shape: TransitionShape = QUINTIC  # of every transition (interpolator.ramp_share)


@dataclass(frozen=True, eq=False, repr=False)
class FeedOutput:
    s_mm: np.ndarray
    vlim_mm_s: np.ndarray
    profile: FeedProfile
    result: PlanResult
    stop_accels: tuple[float, ...] = ()  # the braking acceleration used into each stop


def _scale(s: np.ndarray, inp: FeedInput) -> np.ndarray:
    """Product of the dynamics module's reductions covering each grid point."""
    scale = np.ones(s.shape)
    for r in inp.reductions:
        scale[(s >= r.s_lo_mm) & (s <= r.s_hi_mm)] *= r.factor
    return scale


def feed_limit_mm_s(path: Path, s: np.ndarray, kappa: np.ndarray, inp: FeedInput,
                    ending: bool = False) -> np.ndarray:
    """vlim(s) under the chosen policy, capped by the programmed feed of each piece: on a joint,
    of the piece that starts there, or with ending, of the one that ends there.

    A reduction by factor f scales the normal acceleration kappa v^2, and with it the servo's
    contour error, by f: the feed limit is scaled by sqrt(f)."""
    # path.feed_cap(s), gathered in one go (it masks the grid once per piece)
    feeds = path.columns.feed_mm_s
    index = path.piece_index(s)
    if ending:
        index = np.maximum(np.searchsorted(path.breaks_mm, s, side="left") - 1, 0)
    cap = np.minimum(feeds[index], inp.max_feed_mm_s)
    vlim = chord_error_feed_mm_s(kappa, inp.sample_period_s, inp.chord_tolerance_mm, cap)
    if inp.policy == LimitPolicy.CONTINUOUS:
        with np.errstate(divide="ignore"):
            budget = min(inp.max_accel_mm_s2, inp.centripetal_accel_mm_s2)
            vlim = np.minimum(vlim, np.sqrt(budget / kappa))
    else:
        corner_of = path.columns.corner[path.piece_index(s)]
        for c in sorted_unique(corner_of[corner_of >= 0]):
            mask = corner_of == c
            v_sp = corner_feed_mm_s(kappa[mask], inp.sample_period_s, inp.chord_tolerance_mm,
                                    inp.kappa_bar_per_mm, inp.max_feed_mm_s)
            vlim[mask] = float(np.min(v_sp))
    return vlim * np.sqrt(_scale(s, inp))


def _concat(profiles: list[FeedProfile]) -> FeedProfile:
    """Chain section profiles end to end in time and arc length."""
    if len(profiles) == 1 and profiles[0].t0_s == 0.0 and \
            (not len(profiles[0]) or profiles[0].rows[0, 2] == 0.0):
        return profiles[0]  # one section (no stops): already chained
    parts: list[np.ndarray] = []
    t0 = s0 = 0.0
    for prof in profiles:
        rows = prof.rows.copy()
        if len(rows):
            rows[:, 0] = t0 + rows[:, 0] - prof.t0_s
            rows[:, 2] = s0 + rows[:, 2] - rows[0, 2]
        parts.append(rows)
        t0 += prof.duration_s
        s0 += prof.length_mm
    shape = profiles[0].shape if profiles else QUINTIC
    return FeedProfile.from_rows(np.concatenate(parts) if parts else np.empty((0, 5)), shape)


def _section(s: np.ndarray, vlim: np.ndarray, a: float,
             b: float) -> tuple[np.ndarray, np.ndarray]:
    """The grid of [a, b], its ends exactly a and b: a grid point a rounding error past b
    (49.50000000000001 for 49.5) would otherwise be dropped and the plan end short of b."""
    eps = 1e-9 * max(1.0, abs(b))
    keep = (s >= a - eps) & (s <= b + eps)
    s_sec, v_sec = s[keep].copy(), vlim[keep]
    s_sec[0], s_sec[-1] = a, b
    inner = np.r_[True, np.diff(s_sec) > 0]  # drop points squeezed onto the ends
    s_sec, v_sec = s_sec[inner], v_sec[inner]
    if len(s_sec) > 2 and np.any(np.diff(s_sec) <= 0):
        # Several grid points within eps of an end (a piece of a few nm sampled on its own
        # points, found at a trailing edge of a long program): keep only those between.
        between = np.r_[True, (s_sec[1:-1] > a) & (s_sec[1:-1] < b), True]
        s_sec, v_sec = s_sec[between], v_sec[between]
    return s_sec, v_sec


# A feed limit under this share of the programmed feed at one grid sample alone is a spike (the
# curvature of a turn within a micrometre, as a NURBS makes at a knot where its parametric speed
# nearly vanishes): the plan stops there. Passing it at that feed instead means creeping up to
# and away from it, for the quintics cannot follow the straight rise the grid draws from the
# spike to its neighbours: at 1e-6 mm/s (a cusp next to a weight of 0.01) that took 1.4e7 s.
# A sharp corner of the benchmarks needs 13 % of the feed (butterfly, 42 /mm).
SPIKE_SHARE = 1e-3


def spike_stops_mm(path: Path, s: np.ndarray, vlim: np.ndarray,
                   max_feed_mm_s: float) -> tuple[float, ...]:
    """Path positions of lone samples where vlim is under SPIKE_SHARE of the programmed feed
    (not the path's ends, which are at rest or continue a window)."""
    feeds = path.columns.feed_mm_s
    cap = np.minimum(feeds, max_feed_mm_s)
    if len(s) < 3 or float(vlim.min()) >= SPIKE_SHARE * float(cap.min()):
        return ()  # nothing is that low: the usual case, at the cost of one min()
    low = vlim < SPIKE_SHARE * cap[path.piece_index(s)]
    lone = low[1:-1] & ~low[:-2] & ~low[2:]
    return tuple(float(x) for x in s[1:-1][lone])


def _near(x: float, positions: tuple[float, ...] | list[float]) -> bool:
    return any(abs(x - y) <= STOP_MATCH_MM for y in positions)


def _limits_ending_at_stops(path: Path, s: np.ndarray, kappa: np.ndarray,
                            inp: FeedInput) -> dict[float, float]:
    """vlim at each stop of the path for the section that ends there: under its own piece's
    feed. The next block's, which the stop's grid sample has, once made G1 X10 F3500 then
    G1 X10 Y1 F1.5 creep the whole first line at F1.5 (440 s)."""
    if not path.stops_at_mm:
        return {}
    stops = np.array(path.stops_at_mm)
    near = np.clip(np.searchsorted(s, stops), 0, len(s) - 1)  # the grid sample on the stop
    before = near - (near > 0)
    near = np.where(np.abs(s[before] - stops) < np.abs(s[near] - stops), before, near)
    vlim = feed_limit_mm_s(path, stops, kappa[near], inp, ending=True)
    return dict(zip(path.stops_at_mm, vlim.tolist(), strict=True))


def plan_path_feed(path: Path, inp: FeedInput, cache: PieceSamples | None = None,
                   raise_cruises: bool = True, v_start_mm_s: float = 0.0) -> FeedOutput:
    """Module 3: vlim on a fine grid, then a quintic plan per section, ending at rest.

    Sections are separated by the path's stops (G1 corners brought to zero feed). The first
    starts at v_start_mm_s (a window continuing a cruise of the previous one), the others at
    rest."""
    if cache is None:
        s, kappa = limit_samples(path)
    else:  # a dynamics round on the same path (the loop reuses it) samples it once
        key = ("grid", path)  # the path itself (eq=False: by identity, kept alive by the key)
        if key not in cache:
            cache[key] = limit_samples(path, cache)  # type: ignore[index]
        s, kappa = cache[key]  # type: ignore[index]
    vlim = feed_limit_mm_s(path, s, kappa, inp)
    ending = _limits_ending_at_stops(path, s, kappa, inp)
    spikes = spike_stops_mm(path, s, vlim, inp.max_feed_mm_s)
    extra = [x for x in spikes if not _near(x, path.stops_at_mm)]  # a stop already rests there
    cuts = sorted([0.0, *path.stops_at_mm, *extra, path.length_mm])
    profiles: list[FeedProfile] = []
    used: list[float] = []
    result = PlanResult.OK
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        s_sec, v_sec = _section(s, vlim, a, b)
        if b in ending:
            v_sec = v_sec.copy()
            v_sec[-1] = ending[b]
        if len(v_sec) > 2 and spikes:  # at rest on a spike, its own sample binds no more
            v_sec = v_sec.copy()
            v_sec[0] = v_sec[1] if _near(a, spikes) else v_sec[0]
            v_sec[-1] = v_sec[-2] if _near(b, spikes) else v_sec[-1]
        v0 = v_start_mm_s if a == 0.0 else 0.0
        accel = stop_accel_at(inp.stop_accels, b)
        if accel is None and inp.stop_accel_for is not None:
            accel = model_stop_accel(s_sec, v_sec, inp.max_accel_mm_s2, inp.stop_accel_for,
                                     inp.shape)
        if accel is not None and accel >= inp.max_accel_mm_s2:
            accel = None
        if b not in extra:  # one per stop of the path, in order (the dynamics module's)
            used.append(inp.max_accel_mm_s2 if accel is None else accel)
        parts = [(s_sec, v_sec, inp.max_accel_mm_s2, v0, 0.0)] if accel is None else \
            approach_split(s_sec, v_sec, inp.max_accel_mm_s2, accel, v0, inp.shape)
        for s_part, v_part, a_part, vs, ve in parts:
            plan = plan_feed(s_part - s_part[0], np.maximum(v_part, 1e-6), a_part, vs, ve,
                             raise_cruises=raise_cruises, grid_step_mm=grid_step_mm(path),
                             shape=inp.shape)
            if plan.result != PlanResult.OK:
                result = plan.result
            profiles.append(plan.profile)
    return FeedOutput(s, vlim, _concat(profiles), result, tuple(used))
