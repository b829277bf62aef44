"""Vectorised checks of a chain of quintic feed phases against a sampled feed-limit curve."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.generator.feed.profile import shaped_distance, shaped_speed
from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.numeric import clamp

CHUNK_SAMPLES = 16  # check-sample intervals per chunk of the coarse pass over transitions
# The coarse pass first bounds runs of SUPER_CHUNKS chunks, then the chunks of the runs that
# may exceed SUPER_SHARE * tol (a G1 walk keeps 1 chunk in 600: 2.7 million chunk bounds for
# 10k lines became a sixteenth). A run under that bound holds no chunk above tol/4: the margin,
# an eighth of tol, is ~1e3 times the round-off of a chunk's positions and speeds against its
# run's, so the chunks kept, and with them every check, are the same as chunk by chunk.
SUPER_CHUNKS = 16
SUPER_SHARE = 0.125


@dataclass(frozen=True, eq=False, repr=False)
class LimitCurve:
    """vlim(s), linear between samples on an increasing grid s (mm, mm/s)."""

    s_mm: np.ndarray
    vlim_mm_s: np.ndarray
    step_mm: float | None = None  # the grid's typical step, when the caller knows it

    @property
    def spacing_mm(self) -> float:
        """The typical grid step if given, else the smallest (floored so a degenerate grid cannot
        explode the sample count). A given step keeps the planner's memo valid when pieces of
        the path change and, with them, the odd short step where two pieces meet."""
        if self.step_mm is not None:
            return self.step_mm
        ds = np.diff(self.s_mm)
        return float(max(ds.min(), 1e-7 * (self.s_mm[-1] - self.s_mm[0])))

    def at(self, s_mm: np.ndarray) -> np.ndarray:
        return np.interp(s_mm, self.s_mm, self.vlim_mm_s)

    def span_min(self, a_mm: np.ndarray, b_mm: np.ndarray) -> np.ndarray:
        """min vlim over each [a, b]: the two interpolated ends and every grid sample inside."""
        lo, hi = self._inside(a_mm, b_mm)
        return self._least(lo, hi, self.at(a_mm), self.at(b_mm))

    def span_max(self, a_mm: np.ndarray, b_mm: np.ndarray) -> np.ndarray:
        inner = _range_reduce(np.maximum, self.vlim_mm_s, -np.inf, *self._inside(a_mm, b_mm))
        return np.maximum(inner, np.maximum(self.at(a_mm), self.at(b_mm)))

    def chained_min(self, s_mm: np.ndarray, start: np.ndarray) -> np.ndarray:
        """span_min(s[start], s[start + 1]) for spans that share their ends (a transition's
        chunks): each position is looked up once, not once per span it bounds."""
        after = np.searchsorted(self.s_mm, s_mm, side="right")
        # side="left" differs only at a position on a grid sample (the grid strictly rises).
        before = after - ((after > 0) & (self.s_mm[np.maximum(after - 1, 0)] == s_mm))
        lo = after[start]
        v = self.at(s_mm)
        return self._least(lo, np.maximum(before[start + 1], lo), v[start], v[start + 1])

    def _least(self, lo: np.ndarray, hi: np.ndarray, v_a: np.ndarray,
               v_b: np.ndarray) -> np.ndarray:
        """min vlim over the grid samples lo..hi-1 of each span and its two ends' values."""
        inner = _range_reduce(np.minimum, self.vlim_mm_s, np.inf, lo, hi)
        return np.minimum(inner, np.minimum(v_a, v_b))

    def _inside(self, a_mm: np.ndarray, b_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo = np.searchsorted(self.s_mm, a_mm, side="right")
        hi = np.searchsorted(self.s_mm, b_mm, side="left")
        return lo, np.maximum(hi, lo)


def _range_reduce(op: np.ufunc, vals: np.ndarray, empty: float, lo: np.ndarray,
                  hi: np.ndarray) -> np.ndarray:
    """op over vals[lo:hi] for every pair at once (reduceat on interleaved bounds)."""
    if len(lo) == 0:
        return np.empty(0)
    ext = np.append(vals, empty)  # index len(vals) becomes valid and neutral
    idx = np.empty(2 * len(lo), dtype=np.intp)
    idx[0::2], idx[1::2] = lo, hi
    out = op.reduceat(ext, idx)[0::2]
    return np.where(hi > lo, out, empty)


@dataclass(frozen=True, eq=False, repr=False)
class PhaseArrays:
    """Phases of a planned chain as arrays; seg maps each phase to its planning segment."""

    duration_s: np.ndarray
    s0_mm: np.ndarray
    vs_mm_s: np.ndarray
    ve_mm_s: np.ndarray
    seg: np.ndarray

    @property
    def length_mm(self) -> np.ndarray:
        return 0.5 * self.duration_s * (self.vs_mm_s + self.ve_mm_s)

    def take(self, mask: np.ndarray) -> PhaseArrays:
        return PhaseArrays(self.duration_s[mask], self.s0_mm[mask], self.vs_mm_s[mask],
                           self.ve_mm_s[mask], self.seg[mask])


@dataclass(frozen=True, eq=False, repr=False)
class Violations:
    """Per planning segment: worst excess of v over vlim (mm/s, <= 0 when fine), where, and the
    length of the phase in which it happens."""

    excess_mm_s: np.ndarray
    s_mm: np.ndarray
    phase_len_mm: np.ndarray


def check_phases(ph: PhaseArrays, curve: LimitCurve, n_seg: int, tol: float,
                 shape: TransitionShape = QUINTIC) -> Violations:
    """Worst violation of v <= vlim in each segment: cruises by range minimum, transitions by
    dense samples (close enough that v between them is within tol/2 of linear) plus the exact
    speed at the grid samples inside them. Transition samples are only taken where a coarse
    bound allows an excess above tol/4, so a segment's excess (and where) is exact when it is
    above tol/4 and otherwise only known to be at most tol/4."""
    exc = np.full(n_seg, -np.inf)
    loc = np.zeros(n_seg)
    plen = np.zeros(n_seg)
    lengths = ph.length_mm
    cruise = ph.vs_mm_s == ph.ve_mm_s
    _merge(exc, loc, plen, *_cruise_excess(ph, lengths, cruise, curve))
    for part in _transition_excess(ph, lengths, ~cruise, curve, tol, shape):
        _merge(exc, loc, plen, *part)
    return Violations(exc, loc, plen)


def _merge(exc: np.ndarray, loc: np.ndarray, plen: np.ndarray, seg: np.ndarray, e: np.ndarray,
           s: np.ndarray, ln: np.ndarray) -> None:
    """Keep, per segment, the largest excess among candidates sorted by segment (in place)."""
    if len(seg) == 0:
        return
    starts = np.concatenate(([0], np.flatnonzero(seg[1:] != seg[:-1]) + 1))
    gmax = np.maximum.reduceat(e, starts)
    counts = np.diff(np.append(starts, len(seg)))
    at_max = np.flatnonzero(e == np.repeat(gmax, counts))
    group = np.searchsorted(starts, at_max, side="right") - 1
    _, first = np.unique(group, return_index=True)
    pick = at_max[first]  # first sample reaching the group maximum
    sg = seg[starts]
    better = gmax > exc[sg]
    sg, pick = sg[better], pick[better]
    exc[sg], loc[sg], plen[sg] = e[pick], s[pick], ln[pick]


def _cruise_excess(ph: PhaseArrays, lengths: np.ndarray, mask: np.ndarray,
                   curve: LimitCurve) -> tuple[np.ndarray, ...]:
    a, ln = ph.s0_mm[mask], lengths[mask]
    lo, hi = curve._inside(a, a + ln)
    inner = _range_reduce(np.minimum, curve.vlim_mm_s, np.inf, lo, hi)
    ends = np.minimum(curve.at(a), curve.at(a + ln))
    # Where the minimum sits: an end or the argmin inside (only needed for the violating ones).
    s_min = np.where(curve.at(a) <= curve.at(a + ln), a, a + ln)
    exc = ph.vs_mm_s[mask] - np.minimum(inner, ends)
    for i in np.flatnonzero((inner < ends) & (exc > 0.0)):
        s_min[i] = curve.s_mm[lo[i] + np.argmin(curve.vlim_mm_s[lo[i]:hi[i]])]
    return ph.seg[mask], exc, s_min, ln


def _transition_excess(ph: PhaseArrays, lengths: np.ndarray, mask: np.ndarray,
                       curve: LimitCurve, tol: float,
                       shape: TransitionShape) -> tuple[tuple[np.ndarray, ...], ...]:
    dur, s0, vs, ve = ph.duration_s[mask], ph.s0_mm[mask], ph.vs_mm_s[mask], ph.ve_mm_s[mask]
    if len(dur) == 0:
        return ()
    n = _sample_counts(dur, vs, ve, lengths[mask], curve.spacing_mm, tol, shape)
    ch = _Chunks.build(n, dur, s0, vs, ve, curve, tol, shape)
    # Dense samples only in the chunks that may hold an excess above tol/4 (the very samples a
    # full pass takes there, so the worst points found are the same).
    cnt = ch.j1 - ch.j0 + ~ch.keep_next  # a chunk's last sample unless the next has it
    k = np.repeat(ch.k, cnt)
    j = np.repeat(ch.j0, cnt) + np.arange(len(k)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    tau = j / (n[k] - 1.0)
    s = s0[k] + shaped_distance(tau, dur[k], vs[k], ve[k], shape)
    v = shaped_speed(tau, vs[k], ve[k], shape)
    e = v - curve.at(s)
    # Grid samples inside transitions (where vlim may kink): exact v, by Newton on s(tau) from
    # the interpolated tau; only those in kept chunks (elsewhere v - vlim <= tol/4 there too).
    g = _grid_inside(curve, s0, s0 + lengths[mask])
    gk = clamp(np.searchsorted(s0, curve.s_mm[g], side="right") - 1, 0, len(s0) - 1)
    in_kept = ch.kept_at(curve.s_mm[g], gk)
    g, gk = g[in_kept], gk[in_kept]
    tg = _seed_tau(curve.s_mm[g], gk, k, s, tau)
    for _ in range(3):
        sg = s0[gk] + shaped_distance(tg, dur[gk], vs[gk], ve[gk], shape)
        vg = np.maximum(shaped_speed(tg, vs[gk], ve[gk], shape), 1e-12) * dur[gk]
        tg = clamp(tg - (sg - curve.s_mm[g]) / vg, 0.0, 1.0)
    ge = shaped_speed(tg, vs[gk], ve[gk], shape) - curve.vlim_mm_s[g]
    seg = ph.seg[mask]
    ln = lengths[mask]
    return (seg[k], e, s, ln[k]), (seg[gk], ge, curve.s_mm[g], ln[gk])



def _seed_tau(x: np.ndarray, gk: np.ndarray, k: np.ndarray, s: np.ndarray,
              tau: np.ndarray) -> np.ndarray:
    """tau at x by linear interpolation between samples of its own transition gk (as np.interp
    does inside it; np.interp over all samples may take a neighbour's sample where two
    transitions meet at x, rounding making s step back there), held within their taus."""
    first = np.searchsorted(k, gk, side="left")
    last = np.searchsorted(k, gk, side="right") - 1
    j = np.minimum(np.maximum(np.searchsorted(s, x, side="right") - 1, first),
                   np.maximum(last - 1, first))
    j1 = np.minimum(j + 1, last)
    ds = s[j1] - s[j]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (tau[j1] - tau[j]) / ds * (x - s[j]) + tau[j]
    t = np.where((x == s[j]) | (ds == 0.0), tau[j], t)
    return np.minimum(np.maximum(t, tau[first]), tau[last])


def _bounds(kb: np.ndarray, cb: np.ndarray, n: np.ndarray, dur: np.ndarray, s0: np.ndarray,
            vs: np.ndarray, ve: np.ndarray,
            shape: TransitionShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample index, position and speed of chunk boundary cb of transition kb (each boundary
    by the same operations wherever it is computed, so the same bits)."""
    jb = np.minimum(cb * CHUNK_SAMPLES, n[kb] - 1)
    tau = jb / (n[kb] - 1.0)
    sb = s0[kb] + shaped_distance(tau, dur[kb], vs[kb], ve[kb], shape)
    return jb, sb, shaped_speed(tau, vs[kb], ve[kb], shape)


def _runs(count: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For groups of count[i] + 1 boundaries laid end to end: each boundary's group, its index
    in the group, and the boundaries that start an interval (all but each group's last)."""
    group = np.repeat(np.arange(len(count)), count + 1)
    first = np.cumsum(count + 1) - (count + 1)
    local = np.arange(len(group)) - first[group]
    last = np.zeros(len(group), bool)
    last[first + count] = True
    return group, local, np.flatnonzero(~last)


@dataclass(frozen=True, eq=False, repr=False)
class _Chunks:
    """The kept runs of CHUNK_SAMPLES check-sample intervals per transition: those that may hold
    an excess above tol/4 (a transition is monotone, so on a chunk v <= its larger end speed,
    and vlim >= its minimum over the chunk's span). Runs of SUPER_CHUNKS chunks (supers) are
    bounded first; only the chunks of supers that may exceed SUPER_SHARE * tol are bounded."""

    k: np.ndarray  # per kept chunk: its transition, first and last sample index
    j0: np.ndarray
    j1: np.ndarray
    keep_next: np.ndarray  # the next chunk of the same transition is kept
    sup_first: np.ndarray  # per transition: its first super, and how many it has
    sup_count: np.ndarray
    sup_start_s: np.ndarray  # per super: where it starts (mm), and its first bounded chunk
    sup_fine: np.ndarray  # (-1: its chunks were not bounded, none is kept)
    sup_chunks: np.ndarray  # per super: how many chunks it has
    fine_start_s: np.ndarray  # per bounded chunk: where it starts, whether it is kept
    fine_keep: np.ndarray

    @classmethod
    def build(cls, n: np.ndarray, dur: np.ndarray, s0: np.ndarray, vs: np.ndarray,
              ve: np.ndarray, curve: LimitCurve, tol: float,
              shape: TransitionShape = QUINTIC) -> _Chunks:
        m = (n - 2) // CHUNK_SAMPLES + 1  # chunks per transition (n >= 2 samples)
        first = np.cumsum(m) - m  # per transition: the global index of its first chunk
        ms = (m - 1) // SUPER_CHUNKS + 1  # supers per transition
        kb, sl, i0 = _runs(ms)
        _, sb, vb = _bounds(kb, np.minimum(sl * SUPER_CHUNKS, m[kb]), n, dur, s0, vs, ve, shape)
        vmax = np.maximum(vb[i0], vb[i0 + 1])
        sup_keep = vmax - curve.chained_min(sb, i0) > SUPER_SHARE * tol
        ks, c_lo = kb[i0], sl[i0] * SUPER_CHUNKS  # per super: transition, first chunk
        sup_chunks = np.minimum(c_lo + SUPER_CHUNKS, m[ks]) - c_lo
        todo = np.flatnonzero(sup_keep)
        # The chunks of the supers kept, bounded as chunk by chunk.
        grp, local, f0 = _runs(sup_chunks[todo])
        fk, fc = ks[todo][grp], c_lo[todo][grp] + local
        jb, fsb, fvb = _bounds(fk, fc, n, dur, s0, vs, ve, shape)
        keep = np.maximum(fvb[f0], fvb[f0 + 1]) - curve.chained_min(fsb, f0) > 0.25 * tol
        sup_fine = np.full(len(ks), -1)
        sup_fine[todo] = np.cumsum(sup_chunks[todo]) - sup_chunks[todo]
        kept = f0[keep]
        gid = first[fk[kept]] + fc[kept]  # global chunk index of each kept chunk
        nxt = np.searchsorted(gid, gid + 1)
        keep_next = (nxt < len(gid)) & (gid[np.minimum(nxt, len(gid) - 1)] == gid + 1) \
            & (fc[kept] + 1 < m[fk[kept]])
        return cls(fk[kept], jb[kept], jb[kept + 1], keep_next, np.cumsum(ms) - ms, ms,
                   sb[i0], sup_fine, sup_chunks, fsb[f0], keep)

    def kept_at(self, s_mm: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Whether the chunk of transition k holding s (the later one at a shared boundary) is
        kept: its super by the supers' starts, then the chunk by its super's chunk starts (the
        same chunk as a search over every chunk's start)."""
        sup = clamp(np.searchsorted(self.sup_start_s, s_mm, side="right") - 1,
                    self.sup_first[k], self.sup_first[k] + self.sup_count[k] - 1)
        lo = self.sup_fine[sup]
        out = np.zeros(len(s_mm), bool)
        bounded = np.flatnonzero(lo >= 0)
        if bounded.size:
            lo_b = lo[bounded]
            c = clamp(np.searchsorted(self.fine_start_s, s_mm[bounded], side="right") - 1,
                      lo_b, lo_b + self.sup_chunks[sup[bounded]] - 1)
            out[bounded] = self.fine_keep[c]
        return out


def _sample_counts(dur: np.ndarray, vs: np.ndarray, ve: np.ndarray, length: np.ndarray,
                   h: float, tol: float, shape: TransitionShape = QUINTIC) -> np.ndarray:
    """Samples per transition so that v(s) between two check points deviates from its chord by
    at most tol/2: spacing sqrt(4 tol / |v''|), with |v''| = |j v - a^2| / v^3 <= (J vmax +
    A^2) / vmin^3 (peak jerk J = 10/sqrt(3) dV/T^2, peak a = 15 dV / (8T)); at least half a grid
    step; capped where a transition starts from (near) rest, where vlim is not the binding limit.
    """
    dv = np.abs(ve - vs)
    vmax, vmin = np.maximum(vs, ve), np.minimum(vs, ve)
    vmin = np.maximum(vmin, 0.05 * vmax)
    if shape.is_quintic:
        jerk = 10.0 / np.sqrt(3.0) * dv / dur ** 2
        acc = 15.0 * dv / (8.0 * dur)
    else:
        jerk = shape.jerk_factor * dv / dur ** 2
        acc = shape.peak_factor * dv / dur
    curv = (jerk * vmax + acc * acc) / vmin ** 3
    step = np.minimum(0.5 * h, np.sqrt(4.0 * tol / np.maximum(curv, 1e-300)))
    n = np.ceil(length / step) + 2
    return np.minimum(n, 4.0 * length / h + 2000).astype(np.intp)


def _grid_inside(curve: LimitCurve, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Indices of grid samples inside any of the sorted, disjoint spans [a_i, b_i]."""
    lo = np.searchsorted(curve.s_mm, a, side="left")
    hi = np.searchsorted(curve.s_mm, b, side="right")
    cnt = np.maximum(hi - lo, 0)
    return np.repeat(lo, cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
