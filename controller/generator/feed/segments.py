"""Feed shapes between planning nodes: cruise, accelerate, cruise, decelerate, cruise."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from controller.generator.feed.check import PhaseArrays
from controller.generator.feed.profile import (
    bernstein6_weights,
    quintic_speed,
    transition_duration_s,
    transition_length_mm,
)
from controller.generator.feed.reach import SegmentWindows
from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.numeric import clamp

PEAK_RESOLUTION_BITS = 10  # the cruise-speed search narrows its bracket to 2^-10 (12: same plans
# to the millisecond over 17 programs, 7 % more planning CPU)
PEAK_MAX_STEPS = 40  # bisection every 4th step: 4 steps at least halve the bracket
REST_FRACTION = 1e-7  # of max vlim: node speeds this low never wait (cruise) before moving on
# Over the two benchmarks and 15 generated programs, 17 shape samples and 6 cruise levels (was 33
# and 12) planned 0.06 % less motion time in all, with a sixth less planning CPU.
CRUISE_LEVELS = 6  # candidate cruise speeds when waiting at a node speed is involved
SHAPE_SAMPLES = 17  # samples of a transition's v(s) when fitting it under vlim
_SHAPE_TAU = np.linspace(0.0, 1.0, SHAPE_SAMPLES)
# bernstein6_sum is linear in (vs, ve): distance = T/6 (vs A(tau) + ve B(tau)), speed =
# vs + (ve - vs) C(tau); A, B, C at the shape samples, once.
_W = bernstein6_weights(_SHAPE_TAU)
_SHAPE_A = (_W[0] + 2.0 * _W[1] + 3.0 * (_W[2] + _W[3] + _W[4] + _W[5])) / 6.0
_SHAPE_B = (_W[3] + 2.0 * _W[4] + 3.0 * _W[5]) / 6.0
_SHAPE_C = quintic_speed(_SHAPE_TAU, 0.0, 1.0)


@functools.lru_cache(maxsize=8)
def _shape_tables(shape: TransitionShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C) of the shape samples: distance = T (vs A + ve B), speed = vs + (ve - vs) C."""
    if shape.is_quintic:
        return _SHAPE_A, _SHAPE_B, _SHAPE_C
    big_g = shape.distance(_SHAPE_TAU)
    return _SHAPE_TAU - big_g, big_g, shape.speed(_SHAPE_TAU)


@dataclass(frozen=True, eq=False, repr=False)
class SegmentPlan:
    """Per segment: node speeds, cruise speed, end of the acceleration, start of the braking."""

    a: np.ndarray
    b: np.ndarray
    vi: np.ndarray
    vj: np.ndarray
    vp: np.ndarray
    acc_end: np.ndarray
    dec_start: np.ndarray


def plan_segments(win: SegmentWindows, vi: np.ndarray, vj: np.ndarray, flat: np.ndarray,
                  accel: float, shape: TransitionShape = QUINTIC) -> SegmentPlan:
    """Highest cruise speed V per segment for which the acceleration vi -> V (started as early as
    possible) and the braking V -> vj (ended as late as possible) both fit under vlim.

    A transition sampled at (x_j, c_j) (distance from its start, speed) fits when started at p
    with p + x_j >= first_reach(c_j) for all j: the earliest start is max_j(first_reach - x_j).
    Braking mirrors this with last_reach. Feasibility is monotone in V, so a bisection over all
    segments at once finds it. Flat segments cruise at min(vc, min vlim), which is safe.
    Each segment is planned on its own (see SegmentWindows.take)."""
    a, b = win.a, win.b
    low = np.maximum(vi, vj)
    if shape.is_quintic:
        vc = np.sqrt((16.0 * accel * (b - a) / 15.0 + vi * vi + vj * vj) / 2.0)
    else:
        vc = np.sqrt((2.0 * accel * (b - a) / shape.time_factor + vi * vi + vj * vj) / 2.0)
    # Cruising at or below the segment's minimum of vlim is always safe: the fallback.
    safe = np.maximum(np.minimum(vc, win.curve.span_min(a, b)), low)
    high = np.maximum(np.minimum(vc, win.curve.span_max(a, b)), low)
    allk = np.arange(len(a))
    # Where waiting at vi may last, where waiting at vj may start: fixed for the segment.
    to_vj, from_vi = win.reach_pair(vj, vi, allk)
    reach = (from_vi, to_vj)
    # The windows at the highest and at the safe cruise, in one call (numpy's per-call cost);
    # where the two are one speed (a fifth of a G1 walk's segments), shaped once.
    n = len(a)
    differ = np.flatnonzero(high != safe)
    e_both, d_both = _window(win, np.concatenate((vi, vi[differ])),
                             np.concatenate((vj, vj[differ])),
                             np.concatenate((high, safe[differ])),
                             np.concatenate((allk, differ)), accel, reach, shape)
    e0, d0 = e_both[:n], d_both[:n]
    e_safe, d_safe = e0.copy(), d0.copy()
    e_safe[differ], d_safe[differ] = e_both[n:], d_both[n:]
    ok = (e0 <= d0) & ~flat
    todo = np.flatnonzero(~ok & ~flat & (high > safe))
    lo_v, lo_e0, lo_d0 = _peak_search(win, vi[todo], vj[todo], todo, safe[todo], high[todo],
                                      _gap(e0[todo], d0[todo]), accel, reach,
                                      (e_safe[todo], d_safe[todo]), shape)
    vp = np.where(ok, high, safe)
    vp[todo] = lo_v
    e0[todo], d0[todo] = lo_e0, lo_d0
    _prefer_no_wait(win, vi, vj, safe, vp, e0, d0, accel, flat, reach,
                    (e_safe, d_safe), shape)
    # Flat segments, and those whose window stays empty: accelerate at once, brake at the end
    # (safe when the node speeds are below the segment's minimum; otherwise the check splits or
    # flattens the segment).
    sa = transition_length_mm(vi, vp, accel, shape)
    sd = transition_length_mm(vp, vj, accel, shape)
    bad = ~(e0 <= d0) | flat
    e0 = np.where(bad, a + sa, e0)
    d0 = np.where(bad, np.maximum(b - sd, a + sa), d0)
    return SegmentPlan(a, b, vi, vj, vp, e0, d0)


def _gap(e0: np.ndarray, d0: np.ndarray) -> np.ndarray:
    """Room between the acceleration's end and the braking's start (-inf when none fits)."""
    with np.errstate(invalid="ignore"):
        g = d0 - e0
    return np.where(np.isnan(g), -np.inf, g)


def _peak_search(win: SegmentWindows, vi: np.ndarray, vj: np.ndarray, k: np.ndarray,
                 safe: np.ndarray, high: np.ndarray, gap_high: np.ndarray, accel: float,
                 reach: tuple[np.ndarray, np.ndarray], at_safe: tuple[np.ndarray, np.ndarray],
                 shape: TransitionShape = QUINTIC) -> tuple[np.ndarray, ...]:
    """Highest cruise speed in [safe, high] whose window is not empty (the gap d0 - e0 falls
    with the speed; it is negative at high), to 2^-PEAK_RESOLUTION_BITS of the bracket, with
    the window there: the Illinois method on the gap for all segments at once (bisection where
    the gap is infinite), one _window call per step, from at_safe (the windows at safe, which
    the caller has). Where even safe has no window, safe."""
    lo, hi = safe.copy(), high.copy()
    e_lo, d_lo = at_safe[0].copy(), at_safe[1].copy()  # the window at safe
    g_lo, g_hi = _gap(e_lo, d_lo), gap_high.copy()
    tol = np.ldexp(hi - lo, -PEAK_RESOLUTION_BITS)
    side = np.zeros(lo.size)  # +1: lo moved last, -1: hi moved last
    for step in range(PEAK_MAX_STEPS):
        live = np.flatnonzero((g_lo >= 0.0) & (hi - lo > tol))
        if live.size == 0:
            break
        a, b, ga, gb = lo[live], hi[live], g_lo[live], g_hi[live]
        secant = np.isfinite(gb) & (ga > gb) & (step % 4 != 3)  # every 4th step bisects
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(secant, a + (b - a) * (ga / (ga - gb)), 0.5 * (a + b))
        x = clamp(x, a + 0.5 * tol[live], b - 0.5 * tol[live])
        e, d = _window(win, vi[live], vj[live], x, k[live], accel, reach, shape)
        g = _gap(e, d)
        good = g >= 0.0
        up, down = live[good], live[~good]
        g_hi[up] = np.where(side[up] > 0, 0.5 * g_hi[up], g_hi[up])  # Illinois: stale end
        g_lo[down] = np.where(side[down] < 0, 0.5 * g_lo[down], g_lo[down])
        lo[up], g_lo[up], e_lo[up], d_lo[up] = x[good], g[good], e[good], d[good]
        hi[down], g_hi[down] = x[~good], g[~good]
        side[up], side[down] = 1.0, -1.0
    return lo, e_lo, d_lo


def _prefer_no_wait(win: SegmentWindows, vi: np.ndarray, vj: np.ndarray, safe: np.ndarray,
                    vp: np.ndarray, e0: np.ndarray, d0: np.ndarray, accel: float,
                    flat: np.ndarray, reach: tuple[np.ndarray, np.ndarray],
                    at_safe: tuple[np.ndarray, np.ndarray],
                    shape: TransitionShape = QUINTIC) -> None:
    """Where the highest cruise makes the profile wait at a node speed, a lower cruise may be
    faster overall: try levels between the safe one and the highest, keep the quickest (in place).
    The windows at the two ends are known (at_safe, and e0, d0 at vp) and not shaped again; the
    top level is vp itself only where safe + (vp - safe) rounds back to it. A level whose
    time floor (_time_floor_s) is above the quickest time found so far cannot be the quickest
    and is not shaped: first each segment's level with the lowest floor, then the others still
    under the quickest (a G1 walk: 6 levels in 10)."""
    sa = transition_length_mm(vi, vp, accel, shape)
    sd = transition_length_mm(vp, vj, accel, shape)
    waits = (e0 - sa > win.a * (1.0 + 1e-12) + 1e-12) | (d0 + sd < win.b - 1e-12)
    k = np.flatnonzero(waits & (e0 <= d0) & ~flat & (vp > safe))
    if len(k) == 0:
        return
    frac = np.linspace(0.0, 1.0, CRUISE_LEVELS)
    levels = safe[k, None] + (vp[k] - safe[k])[:, None] * frac
    c0, c1 = np.empty(levels.shape), np.empty(levels.shape)
    c0[:, 0], c1[:, 0] = at_safe[0][k], at_safe[1][k]  # frac 0: safe + 0 is safe
    top_known = levels[:, -1] == vp[k]
    c0[top_known, -1], c1[top_known, -1] = e0[k[top_known]], d0[k[top_known]]
    known = np.zeros(levels.shape, bool)
    known[:, 0] = True
    known[top_known, -1] = True
    kk = np.repeat(k, CRUISE_LEVELS).reshape(levels.shape)
    # The one rounding threshold the times of all these levels share (as one call had it).
    eps = 1e-12 * max(1.0, float(np.abs(win.b[k]).max(initial=0.0)))
    dur = np.full(levels.shape, np.inf)
    _timed(win, vi, vj, levels, c0, c1, kk, known, dur, accel, shape, eps)
    floor = _time_floor_s(win.a[kk], win.b[kk], vi[kk], vj[kk], levels, accel, shape, eps)
    with np.errstate(invalid="ignore"):
        first = np.where(known | (floor > dur.min(axis=1)[:, None]), np.inf, floor)
    one = np.zeros(levels.shape, bool)
    has = np.isfinite(first.min(axis=1))
    one[np.flatnonzero(has), first[has].argmin(axis=1)] = True
    for todo in (one, None):
        if todo is None:  # the others whose floor the quickest so far does not exceed
            todo = ~known & ~(floor > dur.min(axis=1)[:, None])
        rows, cols = np.nonzero(todo)
        kr = kk[rows, cols]
        c0[rows, cols], c1[rows, cols] = _window(win, vi[kr], vj[kr], levels[rows, cols], kr,
                                                 accel, reach, shape)
        _timed(win, vi, vj, levels, c0, c1, kk, todo, dur, accel, shape, eps)
        known |= todo
    # The first quickest, as among all levels: a level not shaped is slower than it.
    best = np.argmin(dur, axis=1)
    pick = np.arange(len(k)), best
    vp[k], e0[k], d0[k] = levels[pick], c0[pick], c1[pick]


def _timed(win: SegmentWindows, vi: np.ndarray, vj: np.ndarray, levels: np.ndarray,
           c0: np.ndarray, c1: np.ndarray, kk: np.ndarray, mask: np.ndarray, dur: np.ndarray,
           accel: float, shape: TransitionShape, eps: float) -> None:
    """dur[mask] = the segment's time at those levels and windows (inf where none fits)."""
    k, lv, w0, w1 = kk[mask], levels[mask], c0[mask], c1[mask]
    t = _segment_time_s(win.a[k], win.b[k], vi[k], vj[k], lv, w0, w1, accel, shape, eps)
    dur[mask] = np.where(w0 <= w1, t, np.inf)


def _time_floor_s(a: np.ndarray, b: np.ndarray, vi: np.ndarray, vj: np.ndarray,
                  vp: np.ndarray, accel: float, shape: TransitionShape,
                  eps: float) -> np.ndarray:
    """At most _segment_time_s at cruise vp for any window: a wait at vi or vj (both at most
    vp) takes no less time than cruising the same stretch at vp, except a wait under eps,
    which counts as none; the relative margin covers the rounding of both sums."""
    sa = transition_length_mm(vi, vp, accel, shape)
    sd = transition_length_mm(vp, vj, accel, shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        move = np.maximum(b - a - sa - sd - 2.0 * eps, 0.0) / vp
    return (move + transition_duration_s(vi, vp, accel, shape)
            + transition_duration_s(vp, vj, accel, shape)) * (1.0 - 1e-9)


def _segment_time_s(a: np.ndarray, b: np.ndarray, vi: np.ndarray, vj: np.ndarray,
                    vp: np.ndarray, e0: np.ndarray, d0: np.ndarray, accel: float,
                    shape: TransitionShape = QUINTIC, eps: float | None = None) -> np.ndarray:
    """Time of: wait at vi, accelerate, cruise at vp from e0 to d0, brake, wait at vj."""
    sa = transition_length_mm(vi, vp, accel, shape)
    sd = transition_length_mm(vp, vj, accel, shape)
    w0, w1 = np.maximum(e0 - sa - a, 0.0), np.maximum(b - d0 - sd, 0.0)
    # As in segment_phases, a wait shorter than eps is a rounding residue of the positions, not
    # a cruise: at a node speed of zero it took forever, and a braking to rest that ended 1e-15
    # mm early made every cruise level but the lowest "infinitely slow" (a 10 mm stretch after
    # a near-stop then crawled at a fifth of the feed).
    if eps is None:
        eps = 1e-12 * max(1.0, float(np.abs(b).max(initial=0.0)))
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        t0 = np.where(w0 > eps, w0 / vi, 0.0)
        t1 = np.where(w1 > eps, w1 / vj, 0.0)
        tc = np.maximum(d0 - e0, 0.0) / vp
    return (t0 + t1 + tc + transition_duration_s(vi, vp, accel, shape)
            + transition_duration_s(vp, vj, accel, shape))


def _window(win: SegmentWindows, vi: np.ndarray, vj: np.ndarray, vp: np.ndarray, k: np.ndarray,
            accel: float, reach: tuple[np.ndarray, np.ndarray],
            shape: TransitionShape = QUINTIC) -> tuple[np.ndarray, np.ndarray]:
    """(end of the acceleration, start of the braking) for cruise speed vp in segments k.

    Between two samples a monotone transition stays inside their bounding box, so testing the
    box corner nearest to vlim (position of one sample, speed of the other) makes a placed
    transition lie under vlim everywhere, not only at the samples. Waiting at vi (vj) before
    (after) the transitions must stay where vlim >= vi (vj): reach = (last_reach(vi),
    first_reach(vj)) for all segments. The peak search calls this once per step, so both
    transitions are shaped in one go (rows: accelerations, then brakings)."""
    n = len(k)
    if n == 0:
        return np.empty(0), np.empty(0)
    a, b = win.a[k], win.b[k]
    v0, v1 = np.concatenate((vi, vp)), np.concatenate((vp, vj))
    length = transition_length_mm(v0, v1, accel, shape)
    x, c = _corners(v0, v1, n, accel, shape)
    reached = win.reach_rows(c, k)
    rest = REST_FRACTION * win.big
    # Acceleration: earliest start with every box corner past where vlim reaches its speed;
    # never a wait at (near) rest, nor one past where vlim stays above vi.
    start = np.maximum(a, (reached[:n] - x[:n]).max(axis=1))
    start[((vi <= rest) & (start > a)) | (start > reach[0][k])] = np.inf
    # Braking: latest end with every box corner before where vlim falls below its speed.
    sd = length[n:]
    end = np.minimum(b, (reached[n:] + (sd[:, None] - x[n:])).min(axis=1))
    end[((vj <= rest) & (end < b)) | (end < reach[1][k])] = -np.inf
    return start + length[:n], end - sd


def _corners(vs: np.ndarray, ve: np.ndarray, n: int, accel: float,
             shape: TransitionShape = QUINTIC) -> tuple[np.ndarray, np.ndarray]:
    """Box corners (distance from start, speed) of the transitions vs -> ve, one row each: the
    first n accelerations (sample j's distance, sample j + 1's speed), then brakings (sample
    j + 1's distance, sample j's speed), j = 0 .. SHAPE_SAMPLES - 2: the samples' numbers, made
    only where a corner takes them."""
    dur = transition_duration_s(vs, ve, accel, shape)
    table_a, table_b, table_c = _shape_tables(shape)
    x = np.empty((len(vs), SHAPE_SAMPLES - 1))
    c = np.empty(x.shape)
    for rows, near, far in ((slice(None, n), slice(None, -1), slice(1, None)),
                            (slice(n, None), slice(1, None), slice(None, -1))):
        np.multiply((dur[rows] * vs[rows])[:, None], table_a[near], out=x[rows])
        x[rows] += (dur[rows] * ve[rows])[:, None] * table_b[near]
        np.multiply((ve[rows] - vs[rows])[:, None], table_c[far], out=c[rows])
    c += vs[:, None]
    return x, c


def segment_phases(sp: SegmentPlan, accel: float,
                   shape: TransitionShape = QUINTIC) -> PhaseArrays:
    """Five phases per segment (cruise vi, accel, cruise V, decel, cruise vj), empty ones out."""
    sa = transition_length_mm(sp.vi, sp.vp, accel, shape)
    sd = transition_length_mm(sp.vp, sp.vj, accel, shape)
    acc0, dec1 = sp.acc_end - sa, sp.dec_start + sd
    s0 = np.column_stack([sp.a, acc0, sp.acc_end, sp.dec_start, dec1])
    lengths = np.column_stack([acc0 - sp.a, sa, sp.dec_start - sp.acc_end, sd, sp.b - dec1])
    # Rounding residues of the positions (a memo row is kept relative to its segment's start and
    # moved back by adding it) are no cruises: below 1e-12 of the path scale a cruise is empty.
    # (Transitions stay, however short: they join the speeds exactly.)
    eps = 1e-12 * max(1.0, float(np.abs(sp.b).max(initial=0.0)))
    cruise = np.array([True, False, True, False, True])
    lengths = np.where(cruise & (lengths <= eps), 0.0, np.maximum(lengths, 0.0))
    vs = np.column_stack([sp.vi, sp.vi, sp.vp, sp.vp, sp.vj])
    ve = np.column_stack([sp.vi, sp.vp, sp.vp, sp.vj, sp.vj])
    # A cruise at zero speed can only be a rounding residue (waiting at rest is never planned).
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        cruise = np.where(vs > 0.0, lengths / vs, 0.0)
    dur = np.where(vs == ve, cruise, transition_duration_s(vs, ve, accel, shape))
    dur = np.where(lengths > 0.0, dur, 0.0)
    seg = np.repeat(np.arange(len(sp.a)), 5).reshape(-1, 5)
    keep = (dur > 0.0).ravel()
    return PhaseArrays(dur.ravel()[keep], s0.ravel()[keep], vs.ravel()[keep], ve.ravel()[keep],
                       seg.ravel()[keep])
