"""Feed planner shortcuts plan the same bits as the plain forms they replace."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import controller.generator.feed.segments as fs
from controller.generator.feed.check import LimitCurve
from controller.generator.feed.planner import PlanResult, clear_memo, plan_feed
from controller.generator.feed.profile import transition_length_mm
from controller.generator.feed.reach import SegmentWindows, _on_key_grid
from controller.generator.feed.shape import QUINTIC, TransitionShape

SHAPES = [QUINTIC, TransitionShape(0.1)]


@st.composite
def corner_curves(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, float]:
    """A plateau with narrow dips at random corners, as a run of short G1 lines gives."""
    length = draw(st.floats(1.0, 30.0))
    vmax = draw(st.floats(10.0, 120.0))
    n = draw(st.integers(100, 3000))
    s = np.linspace(0.0, length, n)
    v = np.full(n, vmax)
    for _ in range(draw(st.integers(1, 40))):
        centre = draw(st.floats(0.0, 1.0)) * length
        width = draw(st.floats(0.005, 0.2))
        depth = draw(st.floats(0.2, 0.97))
        v = np.minimum(v, vmax * (1.0 - depth * np.exp(-0.5 * ((s - centre) / width) ** 2)))
    return s, v, draw(st.floats(300.0, 20000.0))


def _prefer_no_wait_all(
    win, vi, vj, safe, vp, e0, d0, accel, flat, reach, at_safe, shape=QUINTIC
) -> None:
    """The plain form: every cruise level shaped and timed."""
    sa = transition_length_mm(vi, vp, accel, shape)
    sd = transition_length_mm(vp, vj, accel, shape)
    waits = (e0 - sa > win.a * (1.0 + 1e-12) + 1e-12) | (d0 + sd < win.b - 1e-12)
    k = np.flatnonzero(waits & (e0 <= d0) & ~flat & (vp > safe))
    if len(k) == 0:
        return
    frac = np.linspace(0.0, 1.0, fs.CRUISE_LEVELS)
    levels = safe[k, None] + (vp[k] - safe[k])[:, None] * frac
    c0, c1 = np.empty(levels.shape), np.empty(levels.shape)
    c0[:, 0], c1[:, 0] = at_safe[0][k], at_safe[1][k]
    top_known = levels[:, -1] == vp[k]
    c0[top_known, -1], c1[top_known, -1] = e0[k[top_known]], d0[k[top_known]]
    to_shape = np.ones(levels.shape, bool)
    to_shape[:, 0] = False
    to_shape[top_known, -1] = False
    rows, cols = np.nonzero(to_shape)
    kk = k[rows]
    c0[rows, cols], c1[rows, cols] = fs._window(
        win, vi[kk], vj[kk], levels[rows, cols], kk, accel, reach, shape
    )
    levels, c0, c1 = levels.ravel(), c0.ravel(), c1.ravel()
    kk = np.repeat(k, fs.CRUISE_LEVELS)
    dur = fs._segment_time_s(win.a[kk], win.b[kk], vi[kk], vj[kk], levels, c0, c1, accel, shape)
    dur = np.where(c0 <= c1, dur, np.inf).reshape(len(k), fs.CRUISE_LEVELS)
    pick = np.arange(len(k)) * fs.CRUISE_LEVELS + np.argmin(dur, axis=1)
    vp[k], e0[k], d0[k] = levels[pick], c0[pick], c1[pick]


def _window_plain(win, vi, vj, vp, k, accel, reach, shape=QUINTIC):
    """The plain form: all 17 samples of both transitions, searched by _reach_plain."""
    n = len(k)
    if n == 0:
        return np.empty(0), np.empty(0)
    a, b = win.a[k], win.b[k]
    v0, v1 = np.concatenate((vi, vp)), np.concatenate((vp, vj))
    length = transition_length_mm(v0, v1, accel, shape)
    dur = fs.transition_duration_s(v0, v1, accel, shape)
    ta, tb, tc = fs._shape_tables(shape)
    x = (dur * v0)[:, None] * ta
    x += (dur * v1)[:, None] * tb
    c = (v1 - v0)[:, None] * tc
    c += v0[:, None]
    first, last = _reach_plain(win, c[:n, 1:], c[n:, :-1], k)
    rest = fs.REST_FRACTION * win.big
    start = np.maximum(a, (first - x[:n, :-1]).max(axis=1))
    start[((vi <= rest) & (start > a)) | (start > reach[0][k])] = np.inf
    sd = length[n:]
    end = np.minimum(b, (last + (sd[:, None] - x[n:, 1:])).min(axis=1))
    end[((vj <= rest) & (end < b)) | (end < reach[1][k])] = -np.inf
    return start + length[:n], end - sd


def _reach_plain(
    win: SegmentWindows, up: np.ndarray, down: np.ndarray, k: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every level searched, its crossing interpolated from the slots themselves."""
    s, v = win.s_slot, win.v_slot
    near_s, near_v, far_v, kbig_row, never = win._ends
    rows = np.concatenate((k, k + len(win.a)))
    level = np.concatenate((up, down)).reshape(2 * len(k), -1)
    out = np.empty(level.shape)
    for i, row in enumerate(rows):
        for j, lev in enumerate(level[i]):
            if not near_v[row] < lev:
                out[i, j] = near_s[row]
                continue
            key = float(_on_key_grid(np.array(lev)))
            if i < len(k):
                g = int(np.searchsorted(win.fkey, key + kbig_row[row], side="left"))
                p = g - 1
            else:
                g = int(np.searchsorted(win.bkey, kbig_row[row] - key, side="right")) - 1
                p = g + 1
            dv = v[g] - v[p]
            frac = min(max((lev - v[p]) / (dv if dv != 0.0 else 1.0), 0.0), 1.0)
            out[i, j] = s[p] + frac * (s[g] - s[p])
            if g == win._nohit[row] and far_v[row] < lev:
                out[i, j] = never[row]
    return out[: len(k)].reshape(up.shape), out[len(k) :].reshape(down.shape)


def _plan_plain(*args, shape: TransitionShape) -> object:
    saved = fs._prefer_no_wait, fs._window
    fs._prefer_no_wait, fs._window = _prefer_no_wait_all, _window_plain
    try:
        clear_memo()
        return plan_feed(*args, shape=shape)
    finally:
        fs._prefer_no_wait, fs._window = saved
        clear_memo()


@settings(max_examples=30, deadline=None)
@given(corner_curves(), st.sampled_from(SHAPES), st.floats(0.0, 1.0))
def test_plans_are_the_plain_forms_bit_for_bit(
    case: tuple, shape: TransitionShape, start_share: float
) -> None:
    s, vlim, accel = case
    v0 = start_share * float(vlim[0])
    clear_memo()
    fast = plan_feed(s, vlim, accel, v0, 0.0, shape=shape)
    plain = _plan_plain(s, vlim, accel, v0, 0.0, shape=shape)
    assert fast.result is plain.result
    assert fast.rounds == plain.rounds
    assert np.array_equal(fast.profile.rows, plain.profile.rows)


@settings(max_examples=40, deadline=None)
@given(corner_curves(), st.integers(2, 30), st.integers(0, 2**32 - 1), st.integers(1, 16))
def test_reach_pair_is_each_level_searched_alone(
    case: tuple, n_nodes: int, seed: int, per_row: int
) -> None:
    s, vlim, _ = case
    rng = np.random.default_rng(seed)
    inner = np.sort(rng.choice(s[1:-1], size=min(n_nodes, len(s) - 2), replace=False))
    win = SegmentWindows.build(LimitCurve(s, vlim), np.concatenate(([0.0], inner, s[-1:])))
    k = rng.integers(0, len(win.a), size=rng.integers(1, 12))
    top = float(vlim.max())
    shape = (len(k),) if per_row == 1 else (len(k), per_row)
    # Levels at vlim samples themselves (ties) as well as anywhere in [0, max vlim].
    up = np.where(rng.random(shape) < 0.3, rng.choice(vlim, shape), rng.random(shape) * top)
    down = np.where(rng.random(shape) < 0.3, rng.choice(vlim, shape), rng.random(shape) * top)
    got = win.reach_pair(up, down, k)
    want = _reach_plain(win, up, down, k)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


@settings(max_examples=200, deadline=None)
@given(
    st.floats(0.0, 500.0),
    st.floats(1e-4, 50.0),
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
    st.floats(1.0, 3.0),
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
    st.floats(100.0, 20000.0),
    st.sampled_from(SHAPES),
)
def test_time_floor_is_under_every_window_time(
    a: float,
    length: float,
    ri: float,
    rj: float,
    over: float,
    wait0: float,
    wait1: float,
    accel: float,
    shape: TransitionShape,
) -> None:
    """Waits and cruises anywhere in the segment: never quicker than the floor."""
    vmax = 60.0
    vi, vj = ri * vmax, rj * vmax
    vp = np.array([max(vi, vj) * over + 1e-3])
    b = a + length
    sa = float(transition_length_mm(vi, vp, accel, shape)[0])
    sd = float(transition_length_mm(vp, vj, accel, shape)[0])
    room = length - sa - sd
    if room < 0.0:
        return  # no window fits at this cruise
    start = a + wait0 * room
    end = b - wait1 * (b - start - sa - sd)
    args = (np.array([a]), np.array([b]), np.array([vi]), np.array([vj]), vp)
    eps = 1e-12 * max(1.0, abs(b))
    t = fs._segment_time_s(*args, np.array([start + sa]), np.array([end - sd]), accel, shape)
    assert fs._time_floor_s(*args, accel, shape, eps)[0] <= t[0]


def _walk_plan(prefer_no_wait) -> tuple[object, int]:
    """A plan of a long run of corners and the number of windows shaped for it."""
    s = np.linspace(0.0, 40.0, 8001)
    rng = np.random.default_rng(7)
    v = np.full(len(s), 58.3)
    for c in np.cumsum(rng.uniform(0.05, 0.5, 150)):
        v = np.minimum(v, 58.3 * (1.0 - 0.8 * np.exp(-0.5 * ((s - c) / 0.02) ** 2)))
    shaped: list[int] = []
    saved = fs._window, fs._prefer_no_wait

    def counting(win, vi, vj, vp, k, *rest):
        shaped.append(len(k))
        return saved[0](win, vi, vj, vp, k, *rest)

    fs._window, fs._prefer_no_wait = counting, prefer_no_wait
    try:
        clear_memo()
        return plan_feed(s, v, 3000.0, shape=TransitionShape(0.1)), sum(shaped)
    finally:
        fs._window, fs._prefer_no_wait = saved
        clear_memo()


def test_a_walk_shapes_fewer_windows_for_the_same_plan() -> None:
    fast, n_fast = _walk_plan(fs._prefer_no_wait)
    plain, n_plain = _walk_plan(_prefer_no_wait_all)
    assert fast.result is PlanResult.OK
    assert np.array_equal(fast.profile.rows, plain.profile.rows)
    assert n_fast < n_plain
