"""Time-optimal lower bound (docs/algorithms.md, Feed planning) and the quintic plan's
distance to it."""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.generator.feed.limits import path_feed_limit_mm_s
from controller.generator.feed.planner import PlanResult, plan_feed
from controller.generator.feed.time_bound import (
    fb_pass_speed_mm_s,
    time_optimal_bound_s,
    traversal_time_s,
)

REPO = Path(__file__).resolve().parents[2]
VMAX, AMAX, T, DELTA = 3500.0 / 60.0, 2450.0, 1e-3, 1e-3


def _bench():
    spec = importlib.util.spec_from_file_location("bench_time_bound",
                                                  REPO / "bench" / "time_bound.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def curves() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    bench = _bench()
    return {name: bench.arc_length_samples(REPO / "nc_programs" / f"{name}.nc")
            for name in ("naca2415", "butterfly")}


@pytest.mark.parametrize("name, length_mm, expected_s", [
    ("naca2415", 61.78, 1.0884), ("butterfly", 382.86, 6.7017)])
def test_bound_matches_reference(curves: dict, name: str, length_mm: float,
                                 expected_s: float) -> None:
    s, kappa = curves[name]
    assert s[-1] == pytest.approx(length_mm, abs=0.01)
    bound = time_optimal_bound_s(s, kappa, VMAX, AMAX, T, DELTA)
    assert bound == pytest.approx(expected_s, rel=0.005)


def test_naca_plan_close_to_bound(curves: dict) -> None:
    s, kappa = curves["naca2415"]
    s, kappa = s[::2], kappa[::2]  # ~20,000 points (the generator uses 5000 on this curve)
    vlim = path_feed_limit_mm_s(kappa, T, DELTA, AMAX, VMAX)
    t0 = time.perf_counter()
    plan = plan_feed(s, vlim, AMAX)
    cpu = time.perf_counter() - t0
    assert plan.result is PlanResult.OK
    ratio = plan.profile.duration_s / time_optimal_bound_s(s, kappa, VMAX, AMAX, T, DELTA)
    # Quintic starts and stops alone cost 15/16 Vmax/A - Vmax/(2A) = 10 ms each over the bound.
    assert 1.0 < ratio < 1.03
    assert cpu < 1.0  # generous: a loaded CI machine; typically ~25 ms


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.1, 100.0), min_size=3, max_size=40), st.floats(1.0, 1e4),
       st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_fb_pass_matches_loop(vlim: list[float], accel: float, f0: float, f1: float) -> None:
    v = np.array(vlim)
    s = np.cumsum(np.r_[0.0, np.linspace(0.1, 2.0, len(v) - 1)])
    v0, v1 = f0 * v[0], f1 * v[-1]
    ref = np.minimum(v, np.inf) ** 2
    ref[0], ref[-1] = min(ref[0], v0 * v0), min(ref[-1], v1 * v1)
    for i in range(1, len(v)):
        ref[i] = min(ref[i], ref[i - 1] + 2.0 * accel * (s[i] - s[i - 1]))
    for i in range(len(v) - 2, -1, -1):
        ref[i] = min(ref[i], ref[i + 1] + 2.0 * accel * (s[i + 1] - s[i]))
    got = fb_pass_speed_mm_s(s, v, accel, v0, v1)
    assert got ** 2 == pytest.approx(ref, abs=1e-9 * (1.0 + 2.0 * accel * s[-1]))


def test_traversal_time_constant_accel() -> None:
    s = np.linspace(0.0, 1.0, 11)
    v = np.sqrt(2.0 * 100.0 * s)  # from rest at 100 mm/s^2: t = sqrt(2 s / a)
    assert traversal_time_s(s, v) == pytest.approx(np.sqrt(2.0 / 100.0), rel=1e-12)
