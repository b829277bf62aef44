"""Transition shapes: the quintic-edged ramp is a valid transition for every share, the quintic
is the paper's exactly, and plans made with a ramp keep vlim and Amax and are quicker."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import ConfigError, load_config
from controller.generator.feed.planner import PlanResult, plan_feed
from controller.generator.feed.profile import FeedProfile, transition_duration_s
from controller.generator.feed.shape import QUINTIC, TransitionShape
from controller.generator.feed.time_bound import fb_pass_speed_mm_s, traversal_time_s
from tests.generator.test_feed_planner import assert_profile_valid, limit_curves

REPO = Path(__file__).resolve().parents[2]
TAU = np.linspace(0.0, 1.0, 400_001)
shares = st.floats(0.02, 1.0)


def test_quintic_share_is_the_papers_smootherstep() -> None:
    g = QUINTIC.speed(TAU)
    assert np.abs(g - TAU ** 3 * (10.0 - 15.0 * TAU + 6.0 * TAU ** 2)).max() < 1e-14
    assert QUINTIC.peak_factor == 15.0 / 8.0
    assert QUINTIC.jerk_factor == pytest.approx(10.0 / np.sqrt(3.0), rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(shares)
def test_shape_is_a_smooth_transition(share: float) -> None:
    shape = TransitionShape(share)
    g, big_g, a = shape.speed(TAU), shape.distance(TAU), shape.accel(TAU)
    h = TAU[1]
    assert g[0] == 0.0 and g[-1] == pytest.approx(1.0, abs=1e-12)
    assert big_g[0] == 0.0 and big_g[-1] == pytest.approx(0.5, abs=1e-12)
    assert np.all(np.diff(g) >= -1e-15)  # monotone: a transition never turns back
    # G' = g and g' = a (central differences), and a is continuous and peaks at the factor.
    assert np.abs(np.gradient(big_g, h) - g).max() < 1e-6
    assert np.abs(np.gradient(g, h)[1:-1] - a[1:-1]).max() < 1e-4 * shape.jerk_factor
    assert a.max() == pytest.approx(shape.peak_factor, rel=1e-9)
    assert a[0] == 0.0 and a[-1] == 0.0
    # The jerk's bound holds (the check's sample spacing relies on it).
    assert np.abs(np.diff(a) / h).max() <= shape.jerk_factor * (1.0 + 1e-6)
    # Antisymmetric: a transition's length is T (vs + ve) / 2 whatever the share.
    assert np.abs(g + g[::-1] - 1.0).max() < 1e-12


@pytest.mark.parametrize("share", [0.0, -0.1, 1.5])
def test_share_outside_range_is_refused(share: float) -> None:
    with pytest.raises(ValueError, match="ramp_share"):
        TransitionShape(share)


def test_ramp_is_shorter_than_quintic_at_the_same_peak() -> None:
    ramp = TransitionShape(0.1)
    t_q = float(transition_duration_s(0.0, 58.333, 2450.0))
    t_r = float(transition_duration_s(0.0, 58.333, 2450.0, ramp))
    assert t_r == pytest.approx(58.333 / 2450.0 / (1.0 - 0.7 / 15.0), rel=2e-4)  # the margin
    assert t_r < 0.56 * t_q  # 1.024 against 1.875 times the constant-acceleration ramp


@settings(max_examples=40, deadline=None)
@given(limit_curves(), shares)
def test_random_limits_respected_with_any_shape(case: tuple, share: float) -> None:
    s, vlim, accel, v0, v1 = case
    shape = TransitionShape(share)
    plan = plan_feed(s, vlim, accel, v0, v1, shape=shape)
    assert plan.result is PlanResult.OK
    assert plan.profile.shape == shape
    assert_profile_valid(s, vlim, accel, v0, v1, plan.profile)
    fine = np.linspace(0.0, s[-1], 200_001)
    fb = fb_pass_speed_mm_s(fine, np.interp(fine, s, vlim), accel, v0, v1)
    assert plan.profile.duration_s >= traversal_time_s(fine, fb) * (1.0 - 1e-4)


def test_rest_to_rest_line_approaches_the_bound_as_the_share_falls() -> None:
    s = np.linspace(0.0, 20.0, 2001)
    vlim = np.full(s.shape, 58.333)
    bound = traversal_time_s(s, fb_pass_speed_mm_s(s, vlim, 2450.0))
    times = [plan_feed(s, vlim, 2450.0, shape=TransitionShape(r)).profile.duration_s
             for r in (1.0, 0.5, 0.25, 0.1)]
    assert times == sorted(times, reverse=True)
    # Rest to rest at V over L: L / V + p V / A, against the bound's L / V + V / A.
    for r, t in zip((1.0, 0.5, 0.25, 0.1), times, strict=True):
        p = TransitionShape(r).peak_factor
        assert t == pytest.approx(20.0 / 58.333 + p * 58.333 / 2450.0, rel=2e-3)
    assert times[-1] < bound * 1.005 and times[0] > bound * 1.05


def test_profile_keeps_its_shape() -> None:
    rows = np.array([[0.0, 0.01, 0.0, 0.0, 20.0]])
    ramp = FeedProfile.from_rows(rows, TransitionShape(0.2))
    quintic = FeedProfile.from_rows(rows)
    assert ramp != quintic
    _, v_r, a_r = ramp.evaluate(np.array([0.005]))
    _, v_q, a_q = quintic.evaluate(np.array([0.005]))
    assert v_r[0] == pytest.approx(10.0) and v_q[0] == pytest.approx(10.0)
    assert a_r[0] < a_q[0]  # the ramp's peak is lower for the same duration


def test_config_reads_ramp_share_strictly(tmp_path: Path) -> None:
    src = "\n".join(line for line in (REPO / "config/xy_table.yaml").read_text().splitlines()
                    if "ramp_share" not in line) + "\n"
    for share, ok in (("0.25", True), ("1.0", True), ("1.5", False), ("0", False)):
        path = tmp_path / f"share{share}.yaml"
        path.write_text(src.replace("interpolator:\n", f"interpolator:\n  ramp_share: {share}\n"))
        if ok:
            assert load_config(str(path)).interpolator.ramp_share == float(share)
        else:
            with pytest.raises(ConfigError, match="ramp_share"):
                load_config(str(path))
