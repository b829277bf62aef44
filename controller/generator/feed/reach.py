"""Where vlim reaches a speed inside each planning segment: SegmentWindows' searches."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.generator.feed.check import LimitCurve
from controller.numeric import clamp

KEY_STEP_MM_S = 2.0**-20  # speeds in search keys: on this grid, so k * big + v is exact


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
    _step: tuple[np.ndarray, ...]  # 4 of (2 slots,): per answer slot g of a search, _steps
    _far: np.ndarray  # (2 slots,) bool: g is the far end of its segment (no sample reached)

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
        src = clamp(np.repeat(lo - 1 - first, size) + np.arange(int(last[-1]) + 1), 0, len(s) - 1)
        k = np.arange(len(a), dtype=float)
        below, above = (k - 0.5) * big, (k + 0.5) * big  # outside every level's reach
        s_slot, v_slot, f_slot, b_slot = s[src], v[src], fkey[src], bkey[src]
        s_slot[first], s_slot[last] = a, b
        v_slot[first], v_slot[last] = va, vb
        f_slot[first], f_slot[last] = below, above
        b_slot[first], b_slot[last] = below, above
        kbig = k * big
        ends = np.vstack(
            (
                np.concatenate((a, b)),
                np.concatenate((va, vb)),
                np.concatenate((vb, va)),
                np.concatenate((kbig, kbig)),
                np.repeat([np.inf, -np.inf], len(a)),
            )
        )
        far = np.zeros(2 * len(s_slot), bool)
        far[last] = True
        far[len(s_slot) + first] = True
        return cls(
            curve,
            a,
            b,
            lo,
            hi,
            big,
            s_slot,
            v_slot,
            f_slot,
            b_slot,
            ends,
            np.concatenate((last, first)),
            _steps(s_slot, v_slot),
            far,
        )

    def take(self, k: np.ndarray) -> SegmentWindows:
        """Segments k alone (their searches still use the whole grid's keys)."""
        rows = np.concatenate((k, k + len(self.a)))
        return SegmentWindows(
            self.curve,
            self.a[k],
            self.b[k],
            self.lo[k],
            self.hi[k],
            self.big,
            self.s_slot,
            self.v_slot,
            self.fkey,
            self.bkey,
            self._ends[:, rows],
            self._nohit[rows],
            self._step,
            self._far,
        )

    def reach_pair(
        self, up: np.ndarray, down: np.ndarray, k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(first_reach, last_reach) of segments k in one pass (numpy's per-call cost):
        - first_reach: per segment, the smallest s in it with vlim(s) >= up (inf if none);
        - last_reach: per segment, the largest s in it with vlim(s) >= down (-inf if none).
        A level array is (len(k),) or (len(k), n) for n levels per segment; up and down have the
        same shape; levels lie in [0, max vlim]."""
        level = np.concatenate((up, down))
        x = self.reach_rows(level.reshape(len(level), 1 if level.ndim == 1 else level.shape[1]), k)
        return x[: len(k)].reshape(up.shape), x[len(k) :].reshape(down.shape)

    def reach_rows(self, level: np.ndarray, k: np.ndarray) -> np.ndarray:
        """reach_pair of the (2 len(k), n) levels: the first len(k) rows searched from the
        start (first_reach), the others from the end (last_reach)."""
        near_s, near_v, far_v, kbig_row, never = self._ends
        n_up = len(k)
        rows = np.concatenate((k, k + len(self.a)))
        per_row = level.shape[1]
        # Only levels above vlim at the near end are searched (elsewhere the answer is the near
        # end itself): 4 in 10 on a G1 walk. Each searched level takes the operations it took
        # among all of them, so the same bits.
        v_near = near_v[rows]
        below = v_near[:, None] < level
        x = np.repeat(near_s[rows], per_row).reshape(level.shape)
        sel = np.flatnonzero(below)
        n_sel_up = int(np.searchsorted(sel, n_up * per_row))  # searches from the start first
        r = rows[sel // per_row]  # the row (segment and direction) of each searched level
        lev = level.ravel()[sel]
        kbig = kbig_row[r]
        # g: the first (last) slot where the running max reaches level, b (a) when no sample
        # inside does (the slot before it, toward near, is p); a search from the end reads its
        # slot's row of _step in the second half.
        lq = _on_key_grid(lev)
        lq[:n_sel_up] += kbig[:n_sel_up]
        np.subtract(kbig[n_sel_up:], lq[n_sel_up:], out=lq[n_sel_up:])
        g = np.empty(len(sel), np.intp)
        g[:n_sel_up] = np.searchsorted(self.fkey, lq[:n_sel_up], side="left")
        g[n_sel_up:] = np.searchsorted(self.bkey, lq[n_sel_up:], side="right")
        g[n_sel_up:] += len(self.s_slot) - 1
        p_v, dv, p_s, ds = (col[g] for col in self._step)
        frac = np.minimum(np.maximum((lev - p_v) / dv, 0.0), 1.0)
        found = p_s + frac * ds
        # Where the search ended at the far end with vlim there below the level: never reached.
        end = np.flatnonzero(self._far[g])
        never_hit = end[far_v[r[end]] < lev[end]]
        found[never_hit] = never[r[never_hit]]
        x.ravel()[sel] = found
        return x


def _steps(s_slot: np.ndarray, v_slot: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per slot g where a search ends: vlim at p (the slot before it toward the near end), the
    step of vlim from p to g (1 where none: the divisor of the crossing's share), the position
    of p and the step of s from p to g; searches from the start (p = g - 1) in the first half,
    from the end (p = g + 1) in the second. What every search ending there computed, once."""
    n = len(s_slot)
    g = np.arange(n)
    p = np.concatenate((np.maximum(g - 1, 0), np.minimum(g + 1, n - 1)))
    g = np.concatenate((g, g))
    p_v = v_slot[p]
    dv = v_slot[g] - p_v
    p_s = s_slot[p]
    return p_v, np.where(dv != 0.0, dv, 1.0), p_s, s_slot[g] - p_s
