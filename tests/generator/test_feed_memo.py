"""Feed planner memo: plans made with results kept from earlier rounds and calls equal cold ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_feed_planner import limit_curves

import controller.generator.feed.planner as fp
from controller.generator.feed.planner import FeedPlan, plan_feed

REPO = Path(__file__).resolve().parents[2]


def _cold(*args: object, raise_cruises: bool = True) -> FeedPlan:
    fp.clear_memo()
    return plan_feed(*args, raise_cruises=raise_cruises)


def _assert_same(warm: FeedPlan, cold: FeedPlan) -> None:
    assert warm.result is cold.result and warm.rounds == cold.rounds
    assert len(warm.profile.phases) == len(cold.profile.phases)
    np.testing.assert_allclose(warm.profile._arr, cold.profile._arr, rtol=1e-12, atol=1e-12)


def _locally_changed(s: np.ndarray, vlim: np.ndarray, where: float, factor: float) -> np.ndarray:
    """vlim scaled on a short stretch inside (ends untouched), as a dynamics round does (a
    raised stretch keeps the nodes there: only the vlim samples tell the segment changed)."""
    i = int(where * (len(s) - 1))
    lo, hi = max(i - 30, 1), min(i + 30, len(s) - 1)
    out = vlim.copy()
    out[lo:hi] *= factor
    return out


@settings(max_examples=12, deadline=None)
@given(limit_curves(), st.floats(0.05, 0.95), st.sampled_from([0.5, 0.9, 1.1, 1.5]))
def test_memo_across_calls_plans_like_cold(case: tuple, where: float, factor: float) -> None:
    s, vlim, accel, v0, v1 = case
    changed = _locally_changed(s, vlim, where, factor)
    cold_a = _cold(s, vlim, accel, v0, v1, raise_cruises=False)
    cold_a_raised = _cold(s, vlim, accel, v0, v1)
    cold_b = _cold(s, changed, accel, v0, v1)
    # The generator's pattern: a plan, the same input with raise_cruises, a local change.
    fp.clear_memo()
    _assert_same(plan_feed(s, vlim, accel, v0, v1, raise_cruises=False), cold_a)
    _assert_same(plan_feed(s, vlim, accel, v0, v1), cold_a_raised)
    _assert_same(plan_feed(s, changed, accel, v0, v1), cold_b)
    _assert_same(plan_feed(s, vlim, accel, v0, v1), cold_a_raised)


def test_memo_tells_segments_apart_by_their_vlim() -> None:
    """Same nodes and node speeds, vlim lower inside the first segment: not the memo's result."""
    s = np.linspace(0.0, 10.0, 2001)
    vlim_a = 50.0 - 30.0 * np.exp(-0.5 * ((s - 5.0) / 0.5) ** 2)
    vlim_b = np.where((s > 2.0) & (s < 3.0), 30.0, vlim_a)
    n_nodes = 3
    v = np.array([0.0, float(vlim_a[1000]) * 0.9, 0.0])
    accel, tol = 500.0, fp.LIMIT_TOLERANCE * 50.0

    def plan_round(vlim: np.ndarray, memo: fp._Memo) -> tuple:
        nodes = fp.Nodes(np.array([0.0, 5.0, 10.0]), v.copy(), np.zeros(n_nodes - 1, np.intp),
                          np.zeros(n_nodes - 1, bool))
        return fp._plan_round(nodes, v, fp.LimitCurve(s, vlim), accel, tol, memo)

    def fresh() -> fp._Memo:
        return fp._Memo((accel, tol, 0.0, 50.0), fp.plan_segments, {})

    memo = fresh()
    _, viol_a = plan_round(vlim_a, memo)
    ph_warm, viol_warm = plan_round(vlim_b, memo)
    ph_cold, viol_cold = plan_round(vlim_b, fresh())
    assert viol_a.excess_mm_s[0] < 0.0 < viol_cold.excess_mm_s[0]  # the change matters
    for name in ("duration_s", "s0_mm", "vs_mm_s", "ve_mm_s", "seg"):
        np.testing.assert_array_equal(getattr(ph_warm, name), getattr(ph_cold, name))
    np.testing.assert_array_equal(viol_warm.excess_mm_s, viol_cold.excess_mm_s)


def test_memo_keeps_segments_that_only_moved_along_the_path() -> None:
    """A longer stretch early in the path shifts every later segment: the warm plan reuses their
    results (fewer segments planned) and still equals the cold plan."""
    def vlim_of(s: np.ndarray, first_dip_mm: float) -> np.ndarray:
        dips = [(first_dip_mm, 0.3), (first_dip_mm + 3.0, 0.5), (first_dip_mm + 6.0, 0.4)]
        out = np.full(s.shape, 50.0)
        for at, depth in dips:
            out *= 1.0 - depth * np.exp(-0.5 * ((s - at) / 0.2) ** 2)
        return out

    step = 0.005
    s_a = np.arange(0.0, 10.0 + step / 2, step)
    s_b = np.arange(0.0, 10.5 + step / 2, step)  # same grid, 0.5 mm longer before the dips
    a, b = vlim_of(s_a, 1.5), vlim_of(s_b, 2.0)
    planned: list[int] = []
    real = fp.plan_segments

    def counting(win: object, vi: np.ndarray, *args: object) -> object:
        planned.append(len(vi))
        return real(win, vi, *args)

    fp.clear_memo()
    cold_b = plan_feed(s_b, b, 800.0, grid_step_mm=step)
    fp.clear_memo()
    plan_feed(s_a, a, 800.0, grid_step_mm=step)
    try:
        fp.plan_segments = counting
        warm_b = plan_feed(s_b, b, 800.0, grid_step_mm=step)
    finally:
        fp.plan_segments = real
    _assert_same(warm_b, cold_b)
    assert sum(planned) < len(warm_b.profile.phases) // 2  # most segments came from the memo


def test_equal_segments_plan_the_same_bits_cold_and_warm() -> None:
    """A periodic vlim (a circle's, up to rounding) makes many segments with one memo key at
    different places: the plan made again with the memo filled is the same bit for bit (the
    generator's fuzz test caught 2.5e-14 mm between the two on one G2 semicircle)."""
    s = np.arange(1200) * 0.0123 + 0.37  # absolute positions: s - a rounds differently
    vlim = 21.16365165014416 + np.tile([0.0, 2e-15, 4e-15, 2e-15], 300)
    cold = _cold(s, vlim, 2450.0, 10.0, 0.0)
    warm = plan_feed(s, vlim, 2450.0, 10.0, 0.0)
    assert cold.result is warm.result
    assert np.array_equal(warm.profile._arr, cold.profile._arr)


def test_memo_row_from_another_segment_index_plans_like_cold() -> None:
    """Found by the test above with a fresh hypothesis database: the path's last segment is the
    same in the first call (index 27) and after a local change (index 29). When SegmentWindows'
    keys were inexact sums (vlim + k * big), the memo's row for it differed from planning it
    cold by 8e-5 mm/s in cruise speed; the keys are exact now (segments.KEY_STEP_MM_S)."""
    case = np.load(REPO / "tests/data/feed_memo_index_case.npz")
    s, vlim = case["s"], case["vlim"]
    accel, v0, v1 = float(case["accel"]), float(case["v0"]), float(case["v1"])
    changed = _locally_changed(s, vlim, float(case["where"]), float(case["factor"]))
    cold = _cold(s, changed, accel, v0, v1)
    fp.clear_memo()
    plan_feed(s, vlim, accel, v0, v1, raise_cruises=False)
    plan_feed(s, vlim, accel, v0, v1)
    _assert_same(plan_feed(s, changed, accel, v0, v1), cold)
