"""Feed shapes between planning nodes: cruise, accelerate, cruise, decelerate, cruise."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from controller.generator.feed.check import LimitCurve, PhaseArrays
from controller.generator.feed.profile import (
    bernstein6_weights,
    quintic_speed,
    transition_duration_s,
    transition_length_mm,
)
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


KEY_STEP_MM_S = 2.0 ** -20  # speeds in search keys: on this grid, so k * big + v is exact


def _on_key_grid(v: np.ndarray) -> np.ndarray:
    return np.rint(v * (1.0 / KEY_STEP_MM_S)) * KEY_STEP_MM_S


@dataclass(frozen=True, eq=False, repr=False)
class SegmentWindows:
    """Where vlim reaches a level inside each segment [a_k, b_k].

    The running maximum of vlim from a segment's start (end) is monotone inside the segment;
    shifted by k * big per segment it is monotone over the whole grid, so one searchsorted
    answers all queries of all segments at once. Each segment has its own slots: its start a,
    the grid samples inside, its end b, with keys that the searches never stop at (a from the
    start, b from the end) or always stop at (b from the start, a from the end). The crossing
    then always lies between a slot and its neighbour: no case for a search that did not move
    or found nothing inside. Searches from the start (first_reach) and from the end
    (last_reach) share one pass (reach_pair): per segment and direction, one column of _ends (near
    end, vlim at the near and far ends, k * big, the answer when never reached) and of _nohit
    (the slot a search ends at when no sample reaches the level), forward rows first."""

    curve: LimitCurve
    a: np.ndarray
    b: np.ndarray
    lo: np.ndarray  # first grid index inside each segment
    hi: np.ndarray  # last grid index inside each segment (hi < lo: none)
    big: float  # above twice any vlim: levels (0 <= level <= max vlim) stay in their segment
    s_slot: np.ndarray  # per slot: position and vlim
    v_slot: np.ndarray
    fkey: np.ndarray  # running max from each segment's start, + k * big: non-decreasing
    bkey: np.ndarray  # k * big - running max from each segment's end: non-decreasing
    _ends: np.ndarray  # (5, 2 n) float, see above
    _nohit: np.ndarray  # (2 n,) intp

    @classmethod
    def build(cls, curve: LimitCurve, nodes_s: np.ndarray) -> SegmentWindows:
        a, b = nodes_s[:-1], nodes_s[1:]
        s, v = curve.s_mm, curve.vlim_mm_s
        lo = np.searchsorted(s, a, side="right")  # first grid index inside the segment
        hi = np.searchsorted(s, b, side="left") - 1  # last one (hi < lo: none)
        n_in = np.maximum(hi - lo + 1, 0)
        seg = clamp(np.searchsorted(nodes_s, s, side="right") - 1, 0, len(a) - 1)
        # Offsetting each segment by k * big makes one global accumulate restart per segment.
        # The keys are exact sums (big a power of two, vlim on the KEY_STEP grid), so which
        # slot a level reaches does not depend on k: a segment plans the same bits at any
        # index (the planner's memo relies on it).
        big = 2.0 ** math.ceil(math.log2(2.0 * float(v.max()) + 1.0))
        off = seg * big
        vq = _on_key_grid(v)
        fkey = np.maximum.accumulate(vq + off)
        bkey = -np.maximum.accumulate((vq - off)[::-1])[::-1]
        va, vb = curve.at(a), curve.at(b)
        # Slots of segment k: first[k] (a), the samples inside, last[k] (b). The end slots'
        # sources (the samples either side) may lie off the grid; they are overwritten below.
        size = n_in + 2
        last = np.cumsum(size) - 1
        first = last - (size - 1)
        src = clamp(np.repeat(lo - 1 - first, size) + np.arange(int(last[-1]) + 1), 0,
                    len(s) - 1)
        k = np.arange(len(a), dtype=float)
        below, above = (k - 0.5) * big, (k + 0.5) * big  # outside every level's reach
        s_slot, v_slot, f_slot, b_slot = s[src], v[src], fkey[src], bkey[src]
        s_slot[first], s_slot[last] = a, b
        v_slot[first], v_slot[last] = va, vb
        f_slot[first], f_slot[last] = below, above
        b_slot[first], b_slot[last] = below, above
        kbig = k * big
        ends = np.vstack((np.concatenate((a, b)), np.concatenate((va, vb)),
                          np.concatenate((vb, va)), np.concatenate((kbig, kbig)),
                          np.repeat([np.inf, -np.inf], len(a))))
        return cls(curve, a, b, lo, hi, big, s_slot, v_slot, f_slot, b_slot, ends,
                   np.concatenate((last, first)))

    def take(self, k: np.ndarray) -> SegmentWindows:
        """Segments k alone (their searches still use the whole grid's keys)."""
        rows = np.concatenate((k, k + len(self.a)))
        return SegmentWindows(self.curve, self.a[k], self.b[k], self.lo[k], self.hi[k],
                              self.big, self.s_slot, self.v_slot, self.fkey, self.bkey,
                              self._ends[:, rows], self._nohit[rows])

    def reach_pair(self, up: np.ndarray, down: np.ndarray,
                   k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(first_reach, last_reach) of segments k in one pass (numpy's per-call cost):
        - first_reach: per segment, the smallest s in it with vlim(s) >= up (inf if none);
        - last_reach: per segment, the largest s in it with vlim(s) >= down (-inf if none).
        A level array is (len(k),) or (len(k), n) for n levels per segment; up and down have the
        same shape; levels lie in [0, max vlim]."""
        s, v = self.s_slot, self.v_slot
        near_s, near_v, far_v, kbig_row, never = self._ends
        n_up = len(k)
        rows = np.concatenate((k, k + len(self.a)))
        level = np.concatenate((up, down))
        per_row = level.shape[1] if level.ndim == 2 else 1
        # Only levels above vlim at the near end are searched (elsewhere the answer is the near
        # end itself): 4 in 10 on a G1 walk. Each searched level takes the operations it took
        # among all of them, so the same bits.
        v_near = near_v[rows]
        below = (v_near[:, None] < level) if level.ndim == 2 else v_near < level
        x = np.repeat(near_s[rows], per_row).reshape(level.shape)
        sel = np.flatnonzero(below)
        n_sel_up = int(np.searchsorted(sel, n_up * per_row))  # searches from the start first
        r = rows[sel // per_row]  # the row (segment and direction) of each searched level
        lev = level.ravel()[sel]
        kbig = kbig_row[r]
        # g: the first (last) slot where the running max reaches level, b (a) when no sample
        # inside does; p: the slot before it (toward near).
        g = np.empty(len(sel), np.intp)
        p = np.empty(len(sel), np.intp)
        lq = _on_key_grid(lev)
        lq[:n_sel_up] += kbig[:n_sel_up]
        np.subtract(kbig[n_sel_up:], lq[n_sel_up:], out=lq[n_sel_up:])
        g[:n_sel_up] = np.searchsorted(self.fkey, lq[:n_sel_up], side="left")
        g[n_sel_up:] = np.searchsorted(self.bkey, lq[n_sel_up:], side="right")
        g[n_sel_up:] -= 1
        np.subtract(g[:n_sel_up], 1, out=p[:n_sel_up])
        np.add(g[n_sel_up:], 1, out=p[n_sel_up:])
        p_v = v[p]
        dv = v[g] - p_v
        frac = np.minimum(np.maximum((lev - p_v) / np.where(dv != 0.0, dv, 1.0), 0.0), 1.0)
        p_s = s[p]
        found = p_s + frac * (s[g] - p_s)
        # Where the search ended at the far end with vlim there below the level: never reached.
        end = np.flatnonzero(g == self._nohit[r])
        never_hit = end[far_v[r[end]] < lev[end]]
        found[never_hit] = never[r[never_hit]]
        x.ravel()[sel] = found
        return x[:n_up], x[n_up:]


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
    top level is vp itself only where safe + (vp - safe) rounds back to it."""
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
    to_shape = np.ones(levels.shape, bool)
    to_shape[:, 0] = False
    to_shape[top_known, -1] = False
    rows, cols = np.nonzero(to_shape)
    kk = k[rows]
    c0[rows, cols], c1[rows, cols] = _window(win, vi[kk], vj[kk], levels[rows, cols], kk, accel,
                                             reach, shape)
    levels, c0, c1 = levels.ravel(), c0.ravel(), c1.ravel()
    kk = np.repeat(k, CRUISE_LEVELS)
    dur = _segment_time_s(win.a[kk], win.b[kk], vi[kk], vj[kk], levels, c0, c1, accel, shape)
    dur = np.where(c0 <= c1, dur, np.inf).reshape(len(k), CRUISE_LEVELS)
    best = np.argmin(dur, axis=1)
    pick = np.arange(len(k)) * CRUISE_LEVELS + best
    vp[k], e0[k], d0[k] = levels[pick], c0[pick], c1[pick]


def _segment_time_s(a: np.ndarray, b: np.ndarray, vi: np.ndarray, vj: np.ndarray,
                    vp: np.ndarray, e0: np.ndarray, d0: np.ndarray, accel: float,
                    shape: TransitionShape = QUINTIC) -> np.ndarray:
    """Time of: wait at vi, accelerate, cruise at vp from e0 to d0, brake, wait at vj."""
    sa = transition_length_mm(vi, vp, accel, shape)
    sd = transition_length_mm(vp, vj, accel, shape)
    w0, w1 = np.maximum(e0 - sa - a, 0.0), np.maximum(b - d0 - sd, 0.0)
    # As in segment_phases, a wait shorter than eps is a rounding residue of the positions, not
    # a cruise: at a node speed of zero it took forever, and a braking to rest that ended 1e-15
    # mm early made every cruise level but the lowest "infinitely slow" (a 10 mm stretch after
    # a near-stop then crawled at a fifth of the feed).
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
    x, c = _shape(v0, v1, accel, shape)
    first, last = win.reach_pair(c[:n, 1:], c[n:, :-1], k)
    rest = REST_FRACTION * win.big
    # Acceleration: earliest start with every box corner past where vlim reaches its speed;
    # never a wait at (near) rest, nor one past where vlim stays above vi.
    start = np.maximum(a, (first - x[:n, :-1]).max(axis=1))
    start[((vi <= rest) & (start > a)) | (start > reach[0][k])] = np.inf
    # Braking: latest end with every box corner before where vlim falls below its speed.
    sd = length[n:]
    end = np.minimum(b, (last + (sd[:, None] - x[n:, 1:])).min(axis=1))
    end[((vj <= rest) & (end < b)) | (end < reach[1][k])] = -np.inf
    return start + length[:n], end - sd


def _shape(vs: np.ndarray, ve: np.ndarray, accel: float,
           shape: TransitionShape = QUINTIC) -> tuple[np.ndarray, np.ndarray]:
    """Samples (distance from start, speed) of the transitions vs -> ve, one row each."""
    dur = transition_duration_s(vs, ve, accel, shape)
    table_a, table_b, table_c = _shape_tables(shape)
    x = (dur * vs)[:, None] * table_a
    x += (dur * ve)[:, None] * table_b
    v = (ve - vs)[:, None] * table_c
    v += vs[:, None]
    return x, v


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
