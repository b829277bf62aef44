"""Feed planning along a path: quintic transitions and cruises under a feed-limit curve vlim(s)."""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from controller.generator.feed.check import LimitCurve, PhaseArrays, Violations, check_phases
from controller.generator.feed.nodes import (
    STAIR_CAP,
    STAIR_STEP,
    Nodes,
    effective_accel,
    initial_nodes,
)
from controller.generator.feed.profile import FeedProfile
from controller.generator.feed.segments import (
    SegmentPlan,
    SegmentWindows,
    plan_segments,
    segment_phases,
)
from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.generator.feed.time_bound import fb_pass_speed_mm_s
from controller.numeric import sorted_unique

MAX_SPLIT_DEPTH = 8  # a segment split this often is flattened instead (always safe)
FLATTEN_ROUNDS = 3  # rounds that only flatten, before flattening everything
MAX_CRUISE_RAISES = 4  # rounds spent lifting cruises that vlim lets rise later on
MIN_RAISED_CRUISE_S = 0.01  # only cruises at least this long are worth a new node
# A raised cruise is bound by vlim where it starts when vlim is within this many stair steps
# of it there (see _raise_cruises). Over the benchmarks and 15 generated programs, 4 and 8 gave
# the same rounds, motion times and contour errors (2: a round more on one, three motion times
# 1-2 ms apart); on a straight vlim rise 3-20 % steeper than 8A/15, the repair round is saved
# by 8 at every slope, by 4 up to 10 %, by 2 at none.
BOUND_CRUISE_STEPS = 4
LIMIT_TOLERANCE = 1e-7  # relative to max vlim: v <= vlim + tol on the whole profile
MEMO_BYTES = 1 << 24  # size of the memo's vlim keys kept across calls (then it starts afresh)


class PlanResult(Enum):
    """Outcome of plan_feed."""

    OK = "ok"
    START_TOO_FAST = "start speed above the limit or too fast to slow down in time"
    END_TOO_FAST = "end speed above the limit at the end of the path"
    END_UNREACHABLE = "end speed cannot be reached within the path length"
    INVALID_INPUT = "feed-limit curve is not a positive curve on an increasing grid"
    LIMIT_VIOLATED = "no profile under the feed limit was found"


@dataclass(frozen=True, eq=False)
class FeedPlan:
    """A planned feed profile (empty unless result is OK) and the planning rounds it took."""

    profile: FeedProfile
    result: PlanResult
    rounds: int = 0


def plan_feed(s_mm: np.ndarray, vlim_mm_s: np.ndarray, accel_mm_s2: float,
              v_start_mm_s: float = 0.0, v_end_mm_s: float = 0.0,
              raise_cruises: bool = True, grid_step_mm: float | None = None,
              shape: TransitionShape = QUINTIC) -> FeedPlan:
    """Plan v(t) from s=0 at v_start to s=L at v_end, with v <= vlim(s) and |a| <= accel.

    The profile passes every node with zero acceleration. Nodes: the ends, the local minima of
    vlim, and a staircase where vlim is gentler than the quintics can follow. Each round:
    - v^2 passes on the nodes at the quintics' mean acceleration 8A/15 (node speeds reachable);
    - per segment between nodes (vlim unimodal there): wait at vi, accelerate, cruise at V,
      decelerate, wait at vj, with the quickest V whose transitions, placed as early / late as
      fits, lie under vlim (feed_segments: safe by construction up to sampling);
    - check every phase against vlim (feed_check); a segment still crossing vlim gets a node at
      its worst point (below vlim there), or, once split MAX_SPLIT_DEPTH times, is flattened
      (node speeds <= min vlim over it: safe by construction). After FLATTEN_ROUNDS more rounds
      every segment is flattened, so the loop ends after a bounded number of rounds.
    Segments a round leaves unchanged are not planned or checked again (see _Memo).
    s_mm may start anywhere; the profile's s runs from s_mm[0] to s_mm[-1]. grid_step_mm is the
    grid's typical step (default: its smallest); on any result but OK the profile is empty.
    shape: the transitions' shape (the paper's quintic unless a config asks for another).
    """
    s = np.asarray(s_mm, float)
    vlim = np.asarray(vlim_mm_s, float)
    bad = _input_error(s, vlim, v_start_mm_s, v_end_mm_s)
    if bad is not None:
        return FeedPlan(FeedProfile((), shape), bad)
    curve = LimitCurve(s - s[0], vlim, grid_step_mm)
    nodes = initial_nodes(curve, v_start_mm_s, v_end_mm_s, accel_mm_s2, shape)
    tol = LIMIT_TOLERANCE * float(vlim.max())
    memo = _memo_for(curve, accel_mm_s2, tol, shape)
    n_rounds = MAX_SPLIT_DEPTH + FLATTEN_ROUNDS + 2
    best: tuple[float, PhaseArrays, int] | None = None  # duration, phases, round
    raises = 0
    for rnd in range(1, n_rounds + MAX_CRUISE_RAISES + 1):
        v = _node_speeds(nodes, accel_mm_s2, v_start_mm_s, v_end_mm_s, shape)
        if isinstance(v, PlanResult):
            return _result(best, s[0], v, rnd, shape)
        ph, viol = _plan_round(nodes, v, curve, accel_mm_s2, tol, memo, shape)
        if not np.any(viol.excess_mm_s > 0.5 * tol):
            # The profile's duration (FeedProfile sums the durations in the same order).
            dur = float(np.cumsum(ph.duration_s)[-1]) if len(ph.duration_s) else 0.0
            if best is None or dur < best[0]:
                best = (dur, ph, rnd)
            if raise_cruises and raises < MAX_CRUISE_RAISES and _raise_cruises(nodes, ph, curve):
                raises += 1
                continue
            return _result(best, s[0], PlanResult.OK, rnd, shape)
        if best is not None and rnd >= n_rounds - 1:
            # An improvement attempt did not settle: keep the last good plan.
            return _result(best, s[0], PlanResult.OK, rnd, shape)
        if rnd == n_rounds - 1:  # last resort: flatten everything (safe by construction)
            viol = Violations(np.full(len(nodes.s) - 1, np.inf), viol.s_mm, viol.phase_len_mm)
        failed = _repair(nodes, viol, curve, 0.5 * tol, last=rnd > MAX_SPLIT_DEPTH)
        if failed is not None:
            return _result(best, s[0], failed, rnd, shape)
        # Cruises that vlim lets rise later are raised in the same round as the repairs (the
        # next round plans both), which saves a round on the common case of both at once.
        if raise_cruises and raises < MAX_CRUISE_RAISES and rnd <= MAX_SPLIT_DEPTH \
                and _raise_cruises(nodes, ph, curve):
            raises += 1
    return _result(best, s[0], PlanResult.LIMIT_VIOLATED, rnd, shape)


def _result(best: tuple[float, PhaseArrays, int] | None, s0: float, failed: PlanResult,
            rnd: int, shape: TransitionShape) -> FeedPlan:
    """The best plan found (its profile built only now), else the empty plan with failed."""
    if best is None:
        return FeedPlan(FeedProfile((), shape), failed, rnd)
    ph = best[1]
    profile = FeedProfile.from_arrays(ph.duration_s, ph.s0_mm + s0, ph.vs_mm_s, ph.ve_mm_s,
                                      shape=shape)
    return FeedPlan(profile, PlanResult.OK, best[2])


@dataclass(eq=False, repr=False)
class _Memo:
    """Segment results (cruise speed, end of the acceleration, start of the braking, excess,
    where, phase length) by segment: its length, node speeds, flat flag and the vlim samples it
    depends on (the grid inside and one sample either side), positions relative to the segment's
    start (so are the kept positions). A segment is planned and checked on
    its own, so one that a round leaves unchanged keeps its result, and so does one that a later
    call with the same globals (accel, tolerance, grid step, vlim maximum) sees again: the
    generator's raise_cruises attempt repeats its previous call, and its dynamics rounds change
    vlim only locally."""

    globals_: tuple[float, float, float, float, TransitionShape]
    planner: Callable[..., SegmentPlan]  # plan_segments (a test may swap it)
    rows: dict[bytes, int]  # key -> its row of table
    table: np.ndarray = field(default_factory=lambda: np.empty((0, 6)))  # the results
    n_rows: int = 0  # rows of table in use (it grows by doubling)
    key_bytes: int = 0

    def look_up(self, keys: list[bytes]) -> np.ndarray:
        """Each key's row of table, -1 where it has none."""
        get = self.rows.get
        return np.array([get(key, -1) for key in keys], np.intp)

    def store(self, keys: list[bytes], results: np.ndarray) -> None:
        """Remember results (one row per key): rows appended, the keys pointed at them."""
        end = self.n_rows + len(keys)
        if end > len(self.table):
            grown = np.empty((max(end, 2 * len(self.table)), 6))
            grown[:self.n_rows] = self.table[:self.n_rows]
            self.table = grown
        self.table[self.n_rows:end] = results
        self.rows.update(zip(keys, range(self.n_rows, end), strict=True))
        self.n_rows = end
        self.key_bytes += sum(map(len, keys))


_last_memo: list[_Memo] = []  # the previous call's memo (at most one)


def clear_memo() -> None:
    """Forget segment results kept from earlier calls (for benchmarks of cold planning)."""
    _last_memo.clear()


def _memo_for(curve: LimitCurve, accel: float, tol: float, shape: TransitionShape) -> _Memo:
    key = (accel, tol, curve.spacing_mm, float(curve.vlim_mm_s.max()), shape)
    for m in _last_memo:
        if m.globals_ == key and m.planner is plan_segments and m.key_bytes < MEMO_BYTES:
            return m
    m = _Memo(key, plan_segments, {})
    _last_memo[:] = [m]
    return m


def _plan_round(nodes: Nodes, v: np.ndarray, curve: LimitCurve, accel: float, tol: float,
                memo: _Memo, shape: TransitionShape = QUINTIC) -> tuple[PhaseArrays, Violations]:
    """Plan every segment between the nodes and check it against vlim (new segments only)."""
    win = SegmentWindows.build(curve, nodes.s)
    vi, vj = v[:-1], v[1:]
    keys = _segment_keys(win, vi, vj, nodes.flat)
    row = memo.look_up(keys)
    known = row >= 0
    new = np.flatnonzero(~known)
    # zeros, not empty: the += below runs over every row, and np.empty's recycled memory held
    # a NaN now and then (a RuntimeWarning; the new rows are overwritten further down).
    out = np.zeros((len(keys), 6))
    if new.size < len(keys):
        out[known] = memo.table[row[known]]
    # Rows hold positions relative to their segment's start: a segment that moved along the
    # path unchanged (a zone before it was widened) keeps its result.
    out[:, _POSITION_COLUMNS] += win.a[:, None]
    sp = memo.planner(win.take(new), vi[new], vj[new], nodes.flat[new], accel, shape)
    # New segments get their results as remembered ones would: relative to the segment start
    # (x - a, then + a) and, where several new ones share a key (a circle's equal segments),
    # the one row kept for it. Otherwise a plan would differ in the last bits from the same
    # plan made again with the memo filled.
    a_new = win.a[new]
    rep = _representatives([keys[i] for i in new.tolist()])
    rel = np.empty((new.size, 6))
    rel[:, 0], rel[:, 1], rel[:, 2] = sp.vp, sp.acc_end - a_new, sp.dec_start - a_new
    out[new, :3] = rel[rep, :3]
    out[new, 1:3] += a_new[:, None]
    ph = segment_phases(SegmentPlan(win.a, win.b, vi, vj, out[:, 0], out[:, 1], out[:, 2]),
                        accel, shape)
    viol = check_phases(ph.take(~known[ph.seg]), curve, len(keys), tol, shape)
    rel[:, 3], rel[:, 4], rel[:, 5] = (viol.excess_mm_s[new], viol.s_mm[new] - a_new,
                                       viol.phase_len_mm[new])
    out[new, 3:] = rel[rep, 3:]
    out[new, 4] += a_new
    once = sorted_unique(rep)  # one row per key (np.unique would import numpy.ma)
    memo.store([keys[i] for i in new[once].tolist()], rel[once])
    return ph, Violations(out[:, 3], out[:, 4], out[:, 5])


def _representatives(keys: list[bytes]) -> np.ndarray:
    """Per key, the index of its last occurrence (the row the memo keeps for it)."""
    last = {key: j for j, key in enumerate(keys)}
    return np.array([last[key] for key in keys], np.intp)


_POSITION_COLUMNS = [1, 2, 4]  # acc_end, dec_start, where the excess is: stored relative
KEY_DECIMALS = 10  # positions in memo keys, relative to the segment start, rounded to 1e-10 mm


def _segment_keys(win: SegmentWindows, vi: np.ndarray, vj: np.ndarray,
                  flat: np.ndarray) -> list[bytes]:
    """Per segment: its length, node speeds, flat flag and the vlim samples it depends on (the
    grid inside and one either side), positions relative to the segment start, as one byte
    string (one hash per look-up, not one per field). All rows are gathered and rounded into
    one buffer in one go; each key slices it. The four leading numbers have + 0.0, so that a
    -0.0 is the key of 0.0 (as when they were compared as floats)."""
    s, vl = win.curve.s_mm, win.curve.vlim_mm_s
    first = win.lo - 1  # each key holds s[lo - 1:hi + 2] (lo >= 1: a node is never before s[0])
    count = np.maximum(np.minimum(win.hi + 2, len(s)) - first, 0)
    # Row of segment i: rel_b, vi, vj, flat, then count[i] relative positions, count[i] vlim.
    size = 4 + 2 * count
    row0 = np.cumsum(size) - size
    buf = np.empty(int(size.sum()))
    buf[row0] = np.round(win.b - win.a, KEY_DECIMALS) + 0.0
    buf[row0 + 1] = vi + 0.0
    buf[row0 + 2] = vj + 0.0
    buf[row0 + 3] = flat
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    idx = np.repeat(first, count) + local
    at = np.repeat(row0 + 4, count) + local
    buf[at] = np.round(s[idx] - np.repeat(win.a, count), KEY_DECIMALS)
    buf[at + np.repeat(count, count)] = vl[idx]
    data = buf.tobytes()
    ends = ((row0 + size) * 8).tolist()
    return [data[i:j] for i, j in zip((row0 * 8).tolist(), ends, strict=True)]


def _input_error(s: np.ndarray, vlim: np.ndarray, v0: float, v1: float) -> PlanResult | None:
    if s.ndim != 1 or s.shape != vlim.shape or len(s) < 2 or np.any(np.diff(s) <= 0.0):
        return PlanResult.INVALID_INPUT
    if np.any(~np.isfinite(vlim)) or np.any(vlim <= 0.0) or v0 < 0.0 or v1 < 0.0:
        return PlanResult.INVALID_INPUT
    # Within the tolerance every plan keeps to: a look-ahead window continues the cruise of
    # the one before, which may lie that far above vlim (58.33333333333334 mm/s at a cap of
    # 58.333333333333336 failed a valid program: "start speed above the limit").
    tol = LIMIT_TOLERANCE * float(vlim.max())
    if v0 > vlim[0] + tol:
        return PlanResult.START_TOO_FAST
    if v1 > vlim[-1] + tol:
        return PlanResult.END_TOO_FAST
    return None


def _node_speeds(nodes: Nodes, accel: float, v0: float, v1: float,
                 shape: TransitionShape) -> np.ndarray | PlanResult:
    """Node speeds reachable by the transitions both ways (v^2 passes at 8A/15 for quintics,
    at A over the shape's peak factor for another shape)."""
    a_eff = effective_accel(accel, shape)
    v = fb_pass_speed_mm_s(nodes.s, nodes.cap, a_eff, v0, v1)
    # The passes work on v^2 shifted by 2 a s, so they round to ~1e-16 of that scale.
    slack = 1e-12 * (2.0 * a_eff * nodes.s[-1] + v0 * v0 + v1 * v1)
    if v[0] ** 2 < v0 * v0 - slack:
        return PlanResult.START_TOO_FAST
    if v[-1] ** 2 < v1 * v1 - slack:
        return PlanResult.END_UNREACHABLE
    v = np.minimum(v, nodes.cap)  # sqrt rounding must not lift a node above its cap
    v[0], v[-1] = v0, v1
    return v


def _repair(nodes: Nodes, viol: Violations, curve: LimitCurve, tol: float,
            last: bool) -> PlanResult | None:
    """Split or flatten every violating segment; a result when a pinned end speed is to blame."""
    bad = np.flatnonzero(viol.excess_mm_s > tol)
    h = curve.spacing_mm
    a, b, sw = nodes.s[bad], nodes.s[bad + 1], viol.s_mm[bad]
    split = (~nodes.flat[bad]) & (nodes.depth[bad] < MAX_SPLIT_DEPTH) & (not last)
    split &= (sw - a > 2.0 * h) & (b - sw > 2.0 * h)
    failed = _flatten(nodes, bad[~split], curve)
    if failed is not None:
        return failed
    k = bad[split]
    r = np.maximum(0.5 * viol.phase_len_mm[k], 2.0 * h)
    sw = sw[split]
    cap = curve.span_min(np.maximum(sw - r, nodes.s[k]), np.minimum(sw + r, nodes.s[k + 1]))
    depth = nodes.depth[k] + 1
    nodes.s = np.insert(nodes.s, k + 1, sw)
    nodes.cap = np.insert(nodes.cap, k + 1, cap)
    nodes.flat = np.insert(nodes.flat, k + 1, False)
    nodes.depth[k] = depth
    nodes.depth = np.insert(nodes.depth, k + 1, depth)
    return None


def _flatten(nodes: Nodes, k: np.ndarray, curve: LimitCurve) -> PlanResult | None:
    """Cap both ends of segment k at min vlim over it: no phase then rises above that minimum."""
    if len(k) == 0:
        return None
    m = curve.span_min(nodes.s[k], nodes.s[k + 1])
    slack = LIMIT_TOLERANCE * float(curve.vlim_mm_s.max())  # as _input_error allows the ends
    if np.any(m[k == 0] < nodes.cap[0] - slack):
        return PlanResult.START_TOO_FAST  # the pinned start speed cannot stay under vlim
    if np.any(m[k + 1 == len(nodes.s) - 1] < nodes.cap[-1] - slack):
        return PlanResult.END_TOO_FAST
    np.minimum.at(nodes.cap, k, m)
    np.minimum.at(nodes.cap, k + 1, m)
    nodes.flat[k] = True
    return None


def _raise_cruises(nodes: Nodes, ph: PhaseArrays, curve: LimitCurve) -> bool:
    """Add a staircase of nodes inside every long cruise where vlim later rises a stair step
    above it.

    A segment's single accelerate-cruise-decelerate shape must cruise under the lowest vlim it
    crosses after its acceleration; when vlim keeps rising beyond, nodes there let the profile
    step up again (the staircase of nodes.py, found after the fact). All the steps are added
    at once, each where vlim passes the last one's cap by a stair step; one per round took a
    round per step. Where vlim at the first step is within BOUND_CRUISE_STEPS of the cruise,
    the cruise is bound by vlim where it starts and the first node is capped at the cruise
    speed: the plan reaches it there under vlim, while a cap under vlim lets the v^2 passes ask
    the transition into the node for more than its S-shape fits under a steep, straight vlim
    (the airfoil's rise after its nose then needed a repair and a round more). Elsewhere (a
    cruise held down before it starts, vlim far above it) every cap follows vlim."""
    cruise = np.flatnonzero((ph.vs_mm_s == ph.ve_mm_s) & (ph.duration_s >= MIN_RAISED_CRUISE_S))
    steps: list[tuple[float, float]] = []
    for k in cruise:
        v_c = float(ph.vs_mm_s[k])
        a, b = ph.s0_mm[k], ph.s0_mm[k] + ph.length_mm[k]
        lo, hi = np.searchsorted(curve.s_mm, [a, b])
        steps += [(float(curve.s_mm[i]), cap)
                  for i, cap in _raise_steps(curve.vlim_mm_s, int(lo), int(hi), v_c)]
    return _insert_nodes(nodes, steps, curve.spacing_mm)


def _raise_steps(vlim: np.ndarray, lo: int, hi: int, v_c: float) -> list[tuple[int, float]]:
    """(grid index, cap) of the staircase over vlim[lo:hi] above a cruise at v_c."""
    steps: list[tuple[int, float]] = []
    level = v_c * (1.0 + 0.5 * STAIR_STEP)
    while True:
        above = np.flatnonzero(vlim[lo:hi] >= level)
        if above.size == 0:
            return steps
        i = lo + int(above[0])
        cap = float(vlim[i]) / (1.0 + STAIR_CAP * STAIR_STEP)
        if not steps and vlim[i] <= v_c * (1.0 + BOUND_CRUISE_STEPS * STAIR_STEP):
            cap = v_c
        steps.append((i, cap))
        lo, level = i + 1, cap * (1.0 + STAIR_STEP)


def _insert_nodes(nodes: Nodes, steps: list[tuple[float, float]], h: float) -> bool:
    """Nodes at the (position, cap) pairs, sorted by position, each unless within 4 grid steps
    of a node or of one added before it; a split segment's depth is copied to its parts, all
    but the last one not flat. All in one insert per array (numpy's per-call cost)."""
    s_all = nodes.s.tolist()
    added: list[tuple[float, float]] = []
    for s_new, cap in steps:
        j = bisect.bisect_left(s_all, s_new)
        if s_new - s_all[j - 1] < 4.0 * h or s_all[j] - s_new < 4.0 * h:
            continue
        s_all.insert(j, s_new)
        added.append((s_new, cap))
    if not added:
        return False
    s_add, cap_add = np.array(added).T
    j = np.searchsorted(nodes.s, s_add)
    nodes.s = np.insert(nodes.s, j, s_add)
    nodes.cap = np.insert(nodes.cap, j, cap_add)
    nodes.depth = np.insert(nodes.depth, j - 1, nodes.depth[j - 1])
    nodes.flat = np.insert(nodes.flat, j - 1, False)
    return True
