"""Module 3 of the generator: the feed-limit curve along a path and its quintic feed plan."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from controller.generator.feed.limits import chord_error_feed_mm_s, corner_feed_mm_s
from controller.generator.feed.planner import PlanResult, plan_feed
from controller.generator.feed.profile import FeedProfile
from controller.generator.feed.stops import (
    STOP_MATCH_MM,
    approach_split,
    model_stop_accel,
    stop_accel_at,
)
from controller.geometry.curves import Curve
from controller.geometry.path import Path, Piece, PieceKind
from controller.numeric import sorted_unique

# Feed-limit samples per run, their spacing clamped: at most 35 um, under the 58 um a sample
# period covers at full feed. Measured over 17 programs, 35 um planned 0.05 % less motion time
# than 20 um (and fewer dynamics rounds), with half the samples on the long ones.
GRID_POINTS = 5000
MIN_SPACING_MM = 0.002
MAX_SPACING_MM = 0.035


class LimitPolicy(StrEnum):
    CONTINUOUS = "continuous"  # ph-lookahead: curvature feed everywhere, contour-derived
    CORNER_PLATEAU = "corner-plateau"  # Tsai 2008: V_sp = min(V_af, V_cf) held over each zone


@dataclass(frozen=True)
class Reduction:
    """Dynamics module's verdict: scale the centripetal budget by factor over [s_lo, s_hi]."""

    s_lo_mm: float
    s_hi_mm: float
    factor: float


@dataclass(frozen=True)
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
    # (s of a stop, braking acceleration into it), from the dynamics module (feed/stops.py)
    stop_accels: tuple[tuple[float, float], ...] = field(default=())
    # the dynamics module's first guess for stops without one: approach speed -> acceleration
    stop_accel_for: Callable[[float], float] | None = None


@dataclass(frozen=True, eq=False)
class FeedOutput:
    s_mm: np.ndarray
    vlim_mm_s: np.ndarray
    profile: FeedProfile
    result: PlanResult
    stop_accels: tuple[float, ...] = ()  # the braking acceleration used into each stop


# Keyed by the curve itself, not id(curve): an id is only unique among live objects, and a
# blend freed between dynamics rounds would hand its id (and its samples) to the next one.
PieceSamples = dict[tuple[Curve, float, float, int], tuple[np.ndarray, np.ndarray]]


def _speed_and_kappa(curve: Curve, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = curve.evaluate(u, 2)
    speed2 = np.einsum("ni,ni->n", d[1], d[1])
    speed = np.sqrt(speed2)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.abs(d[1, :, 0] * d[2, :, 1] - d[1, :, 1] * d[2, :, 0]) / (speed2 * speed)
    return speed, np.where(np.isfinite(kappa), kappa, 0.0)  # |C'| = 0: nan or +inf


def _trapezoid_s(u: np.ndarray, speed: np.ndarray, length_mm: float) -> np.ndarray:
    """Arc length at u by the trapezoid rule on |C'|, rescaled to length_mm."""
    s = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u))))
    if s[-1] > 0:
        s *= length_mm / s[-1]
    return s


def _piece_samples(p: Piece, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(local s, kappa) at n parameters of a piece; s by the trapezoid rule on |C'| rescaled to
    the exact piece length (planning needs positions to ~1e-6 mm, not the table's 1e-12).
    A NURBS piece that n even parameters do not resolve is sampled by knot span instead
    (_knot_span_samples), with as many samples as its length needs."""
    u = np.linspace(p.u0, p.u1, n)
    speed, kappa = _speed_and_kappa(p.curve, u)
    s = _trapezoid_s(u, speed, p.length_mm)
    inner = _inner_knots(p)
    if inner is not None and not _resolved(p, s, kappa, inner, n):
        return _knot_span_samples(p, inner, p.length_mm / (n - 1))
    return s, kappa


# Uniform parameters resolve a NURBS piece when no two samples are further apart than this
# many times their mean spacing (the programs of nc_programs/ and the benchmarks: at most 4.3)
# and no knot's curvature, from either side, exceeds the samples' largest by this factor
# (there: at most 0.95). A quadratic with knot spans 1 and 9999 put one sample on its first
# 5 mm, and its 22 degree turn within 0.5 um of a knot between samples: passed at full feed,
# the tool was 34.6 um off the path.
SPARSE_GAP = 8.0
KNOT_KAPPA = 1.5


def _inner_knots(p: Piece) -> np.ndarray | None:
    knots = getattr(p.curve, "knots", None)
    if knots is None or p.kind != PieceKind.NURBS or not p.u1 > p.u0 or p.length_mm <= 0.0:
        return None
    return np.unique(knots[(knots > p.u0) & (knots < p.u1)])


def _knot_kappa(curve: Curve, knots: np.ndarray) -> np.ndarray:
    """Curvature at each knot, the larger of its two sides (it jumps where C'' does)."""
    if not knots.size:
        return np.zeros(0)
    right = _speed_and_kappa(curve, knots)[1]
    left = _speed_and_kappa(curve, np.nextafter(knots, -np.inf))[1]
    return np.maximum(left, right)


def _resolved(p: Piece, s: np.ndarray, kappa: np.ndarray, inner: np.ndarray, n: int) -> bool:
    if float(np.diff(s).max()) > SPARSE_GAP * p.length_mm / (n - 1):
        return False
    peak = _knot_kappa(p.curve, inner)
    return not (peak.size and float(peak.max()) > KNOT_KAPPA * float(kappa.max()))


def _knot_span_samples(p: Piece, inner: np.ndarray,
                       spacing_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(local s, kappa) of a NURBS piece sampled span by span: each knot span gets even
    parameters at about spacing_mm (at least 8 intervals), its arc length exact from the curve's
    table, and each knot the larger curvature of its two sides."""
    bounds = np.concatenate(([p.u0], inner, [p.u1]))
    s_bounds = p.curve.s_of_u(bounds)
    s_bounds = s_bounds - s_bounds[0]
    span_mm = np.diff(s_bounds)
    counts = np.maximum(np.ceil(span_mm / spacing_mm).astype(int), 8)
    u_parts, s_parts, k_parts = [], [], []
    for i, m in enumerate(counts.tolist()):
        u = np.linspace(bounds[i], bounds[i + 1], m + 1)
        speed, kappa = _speed_and_kappa(p.curve, u)
        u_parts.append(u[:-1])
        s_parts.append(s_bounds[i] + _trapezoid_s(u, speed, float(span_mm[i]))[:-1])
        k_parts.append(kappa[:-1])
    u = np.concatenate((*u_parts, bounds[-1:]))
    s = np.concatenate((*s_parts, [float(s_bounds[-1])]))
    kappa = np.concatenate((*k_parts, _speed_and_kappa(p.curve, bounds[-1:])[1]))
    at_knot = np.searchsorted(u, inner)
    kappa[at_knot] = np.maximum(kappa[at_knot], _knot_kappa(p.curve, inner))
    s *= p.length_mm / s[-1] if s[-1] > 0 else 1.0
    return s, kappa


def _batches(todo: list[tuple[Piece, int]], cache: PieceSamples
             ) -> Iterator[tuple[int, list[Piece], np.ndarray]]:
    """The pieces to sample grouped by sample count, each group with its parameters (one row
    per piece); a group with a zero parameter step is sampled piece by piece into the cache
    instead (linspace treats a zero step apart)."""
    by_count: dict[int, list[Piece]] = {}
    for p, n in todo:
        by_count.setdefault(n, []).append(p)
    for n, ps in by_count.items():
        u0, u1 = np.array([p.u0 for p in ps]), np.array([p.u1 for p in ps])
        if np.any(u1 == u0):
            for p in ps:
                cache[(p.curve, p.u0, p.u1, n)] = _piece_samples(p, n)
            continue
        yield n, ps, np.linspace(u0, u1, n, axis=1)


def _store(ps: list[Piece], n: int, u: np.ndarray, speed: np.ndarray, kappa: np.ndarray,
           cache: PieceSamples) -> None:
    """_piece_samples' trapezoids of |C'| on each row, rescaled to its piece's length, into
    the cache with the row's curvature."""
    s = np.zeros(u.shape)
    np.cumsum(0.5 * (speed[:, 1:] + speed[:, :-1]) * np.diff(u, axis=1), axis=1, out=s[:, 1:])
    length = np.array([p.length_mm for p in ps])
    last = s[:, -1].copy()
    scale = length / np.where(last > 0, last, 1.0)
    s[last > 0] *= scale[last > 0, None]
    for p, row_s, row_k in zip(ps, s, np.broadcast_to(kappa, u.shape), strict=True):
        cache[(p.curve, p.u0, p.u1, n)] = (row_s, row_k)


def _line_samples(todo: list[tuple[Piece, int]], cache: PieceSamples) -> None:
    """_piece_samples of many LINE pieces at once, into the cache: the same operations on
    arrays of pieces with the same count (curvature 0; the trapezoids of a constant speed,
    then rescaled to the piece length), so the same numbers, without numpy's cost per call
    on every line of a G1 program."""
    for n, ps, u in _batches(todo, cache):
        dx = np.array([p.curve.p1[0] - p.curve.p0[0] for p in ps])  # type: ignore[attr-defined]
        dy = np.array([p.curve.p1[1] - p.curve.p0[1] for p in ps])  # type: ignore[attr-defined]
        speed = np.broadcast_to(np.sqrt(dx * dx + dy * dy)[:, None], u.shape)
        _store(ps, n, u, speed, np.zeros(n), cache)


def _ph_samples(todo: list[tuple[Piece, int]], cache: PieceSamples) -> None:
    """_piece_samples of many PH pieces at once, into the cache: PhQuintic.evaluate's
    operations (w, w^2, 2 w w') on an array of pieces with the same count, then the same
    speed, curvature and trapezoids, so the same numbers (tests/generator/test_plan_caches.py
    compares them bit for bit); a G1 program has a PH blend at every joint."""
    for n, ps, x in _batches(todo, cache):
        w0, w1, w2 = (np.array([getattr(p.curve, k) for p in ps])[:, None]
                      for k in ("w0", "w1", "w2"))
        w = w0 * (1 - x) ** 2 + 2 * w1 * (1 - x) * x + w2 * x * x
        d1 = w ** 2
        d2 = 2 * w * (2 * ((w1 - w0) * (1 - x) + (w2 - w1) * x))
        dx, dy, ddx, ddy = d1.real, d1.imag, d2.real, d2.imag
        speed2 = dx * dx + dy * dy
        speed = np.sqrt(speed2)
        with np.errstate(divide="ignore", invalid="ignore"):
            kappa = np.abs(dx * ddy - dy * ddx) / (speed2 * speed)
        _store(ps, n, x, speed, np.where(np.isfinite(kappa), kappa, 0.0), cache)


def grid_step_mm(path: Path) -> float:
    """Target spacing of the feed-limit grid (each piece's own step is at most this)."""
    return float(np.clip(path.length_mm / GRID_POINTS, MIN_SPACING_MM, MAX_SPACING_MM))


def limit_samples(path: Path, cache: PieceSamples | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(s, kappa) on a fine grid, each piece sampled in its own parameter (no inversion needed).

    At a joint both sides are sampled and the larger curvature is kept (curvature may jump)."""
    spacing = grid_step_mm(path)
    cache = {} if cache is None else cache
    pieces = path.pieces
    counts = [max(math.ceil(p.length_mm / spacing), 8) + 1 for p in pieces]
    keys = [(p.curve, p.u0, p.u1, n) for p, n in zip(pieces, counts, strict=True)]
    missing = [i for i, key in enumerate(keys) if key not in cache]
    for kind, batch in ((PieceKind.LINE, _line_samples), (PieceKind.PH, _ph_samples)):
        batch([(pieces[i], counts[i]) for i in missing if pieces[i].kind == kind], cache)
    for i in missing:
        if keys[i] not in cache:
            cache[keys[i]] = _piece_samples(pieces[i], counts[i])
    rows = [cache[key] for key in keys]
    counts = [len(r[0]) for r in rows]  # a NURBS piece sampled by knot span has its own count
    # Each piece's samples moved to where it starts on the path, all at once (p.s0_mm + s).
    s = np.repeat([p.s0_mm for p in pieces], counts) + np.concatenate([r[0] for r in rows])
    kappa = np.concatenate([r[1] for r in rows])
    # The pieces follow each other: each one's first sample is the previous one's last point.
    # Keep the larger curvature there, drop the duplicate, then anything not strictly ahead.
    first = np.cumsum(counts)[:-1]
    kappa[first - 1] = np.maximum(kappa[first - 1], kappa[first])
    s, kappa = np.delete(s, first), np.delete(kappa, first)
    if np.all(np.diff(s) > 1e-12):
        return s, kappa
    order = np.lexsort((-kappa, s))  # a degenerate piece: by s, larger curvature first
    s, kappa = s[order], kappa[order]
    keep = np.r_[True, np.diff(s) > 1e-12]
    return s[keep], kappa[keep]


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
    feeds = np.array([p.feed_mm_s for p in path.pieces])
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
        corner_of = np.array([p.corner for p in path.pieces])[path.piece_index(s)]
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
    return FeedProfile.from_rows(np.concatenate(parts) if parts else np.empty((0, 5)))


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
    feeds = np.array([p.feed_mm_s for p in path.pieces])
    cap = np.minimum(feeds, max_feed_mm_s)
    if len(s) < 3 or float(vlim.min()) >= SPIKE_SHARE * float(cap.min()):
        return ()  # nothing is that low: the usual case, at the cost of one min()
    low = vlim < SPIKE_SHARE * cap[path.piece_index(s)]
    lone = low[1:-1] & ~low[:-2] & ~low[2:]
    return tuple(float(x) for x in s[1:-1][lone])


def _near(x: float, positions: tuple[float, ...] | list[float]) -> bool:
    return any(abs(x - y) <= STOP_MATCH_MM for y in positions)


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
    # A section ending at a stop brakes to rest under its own piece's feed: the next block's,
    # which its last grid sample has, once made G1 X10 F3500 then G1 X10 Y1 F1.5 creep the
    # whole first line at F1.5 (440 s).
    stops = np.array(path.stops_at_mm)
    at_stop = np.flatnonzero(np.isin(s, stops))
    ending = dict(zip(s[at_stop].tolist(),
                      feed_limit_mm_s(path, s[at_stop], kappa[at_stop], inp, True).tolist(),
                      strict=True))
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
            accel = model_stop_accel(s_sec, v_sec, inp.max_accel_mm_s2, inp.stop_accel_for)
        if accel is not None and accel >= inp.max_accel_mm_s2:
            accel = None
        if b not in extra:  # one per stop of the path, in order (the dynamics module's)
            used.append(inp.max_accel_mm_s2 if accel is None else accel)
        parts = [(s_sec, v_sec, inp.max_accel_mm_s2, v0, 0.0)] if accel is None else \
            approach_split(s_sec, v_sec, inp.max_accel_mm_s2, accel, v0)
        for s_part, v_part, a_part, vs, ve in parts:
            plan = plan_feed(s_part - s_part[0], np.maximum(v_part, 1e-6), a_part, vs, ve,
                             raise_cruises=raise_cruises, grid_step_mm=grid_step_mm(path))
            if plan.result != PlanResult.OK:
                result = plan.result
            profiles.append(plan.profile)
    return FeedOutput(s, vlim, _concat(profiles), result, tuple(used))
