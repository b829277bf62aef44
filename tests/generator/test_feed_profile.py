"""Quintic Bernstein feed transitions: closed forms against numerics and the check values
of docs/algorithms.md, Feed planning."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from controller.generator.feed.path_plan import _concat
from controller.generator.feed.planner import PlanResult, plan_feed
from controller.generator.feed.profile import (
    FeedPhase,
    FeedProfile,
    bernstein6_distance,
    quintic_accel,
    quintic_distance,
    quintic_speed,
    transition_duration_s,
    transition_length_mm,
)

VMAX = 3500.0 / 60.0
AMAX = 2450.0
# Speeds like 2e-313 mm/s make the transition's duration underflow and the peak acceleration
# lose digits; no feed is that small, so rest or at least 1e-9 mm/s.
speeds = st.one_of(st.just(0.0), st.floats(1e-9, 300.0))


# quad warns on an interval ending near the smallest normal float (tau ~1e-308, which hypothesis
# draws now and then); its result is still checked below.
@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@settings(max_examples=40, deadline=None)
@given(vs=speeds, ve=speeds, tau=st.floats(0.0, 1.0))
def test_distance_closed_form_matches_integration(vs: float, ve: float, tau: float) -> None:
    dur = max(float(transition_duration_s(vs, ve, AMAX)), 1e-3)
    numeric, _ = quad(lambda x: float(quintic_speed(x, vs, ve)) * dur, 0.0, tau,
                      epsabs=1e-13, epsrel=1e-13)
    assert float(bernstein6_distance(tau, dur, vs, ve)) == pytest.approx(numeric, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(vs=speeds, ve=speeds)
def test_transition_peak_accel_is_amax_and_ends_are_flat(vs: float, ve: float) -> None:
    dur = float(transition_duration_s(vs, ve, AMAX))
    if dur == 0.0:
        return
    tau = np.linspace(0.0, 1.0, 20001)
    a = quintic_accel(tau, dur, vs, ve)
    assert np.abs(a).max() == pytest.approx(AMAX, rel=1e-9)
    assert a[0] == 0.0 and a[-1] == 0.0
    # Speed by finite differences of the distance, acceleration by those of the speed.
    s = bernstein6_distance(tau, dur, vs, ve)
    v = quintic_speed(tau, vs, ve)
    dt = dur * (tau[1] - tau[0])
    assert np.allclose(np.gradient(s, dt)[1:-1], v[1:-1], atol=1e-6 * (1.0 + max(vs, ve)))
    assert float(s[-1]) == pytest.approx(float(transition_length_mm(vs, ve, AMAX)), rel=1e-12)


def test_transition_check_values() -> None:
    assert float(transition_duration_s(0.0, 58.333, AMAX)) == pytest.approx(0.044643, abs=1e-6)
    assert float(transition_length_mm(0.0, 58.333, AMAX)) == pytest.approx(1.302083, abs=1e-4)


def _plan_const(length_mm: float, v0: float = 0.0, v1: float = 0.0) -> FeedProfile:
    s = np.linspace(0.0, length_mm, 2001)
    plan = plan_feed(s, np.full_like(s, VMAX), AMAX, v0, v1)
    assert plan.result is PlanResult.OK
    return plan.profile


def test_check_value_100mm_rest_to_rest() -> None:
    assert _plan_const(100.0).duration_s == pytest.approx(1.75893, abs=1e-5)


def test_check_value_1mm_peak_speed() -> None:
    prof = _plan_const(1.0)
    _, v, a = prof.evaluate(np.linspace(0.0, prof.duration_s, 20001))
    assert v.max() == pytest.approx(36.148, abs=1e-3)
    assert prof.duration_s == pytest.approx(0.0553, abs=1e-4)
    assert np.abs(a).max() == pytest.approx(AMAX, rel=1e-6)


def test_check_value_5mm_40_to_20() -> None:
    prof = _plan_const(5.0, 40.0, 20.0)
    durations = [p.duration_s for p in prof.phases]
    assert len(durations) == 3
    assert durations == pytest.approx([0.0140, 0.0542, 0.0293], abs=1e-4)


def test_profile_evaluate_any_shape_and_clamped() -> None:
    prof = _plan_const(10.0, 5.0, 0.0)
    t = np.linspace(-0.1, prof.duration_s + 0.1, 60).reshape(3, 4, 5)
    s, v, a = prof.evaluate(t)
    assert s.shape == v.shape == a.shape == t.shape
    assert s.min() == 0.0 and s.max() == pytest.approx(10.0, abs=1e-12)
    assert v.ravel()[0] == 5.0 and v.ravel()[-1] == 0.0


def test_profile_exact_at_joints() -> None:
    prof = _plan_const(20.0, 10.0, 3.0)
    for p, q in zip(prof.phases[:-1], prof.phases[1:], strict=True):
        assert p.t0_s + p.duration_s == pytest.approx(q.t0_s, abs=1e-15)
        assert p.s0_mm + p.length_mm == pytest.approx(q.s0_mm, abs=1e-12)
        assert p.v_end_mm_s == q.v_start_mm_s
        s, v, a = prof.evaluate(np.array([q.t0_s]))
        assert s[0] == pytest.approx(q.s0_mm, abs=1e-12) and v[0] == q.v_start_mm_s
        assert a[0] == 0.0


def test_feed_phase_length() -> None:
    assert FeedPhase(0.0, 2.0, 0.0, 1.0, 3.0).length_mm == 4.0


@settings(max_examples=60, deadline=None)
@given(vs=speeds, ve=speeds, tau=st.floats(0.0, 1.0))
def test_power_form_distance_matches_bernstein_form(vs: float, ve: float, tau: float) -> None:
    """The planner's checks use the power form; the profile's own evaluation the Bernstein form."""
    dur = max(float(transition_duration_s(vs, ve, AMAX)), 1e-3)
    t = np.array([tau])
    assert float(quintic_distance(t, dur, vs, ve)[0]) == pytest.approx(
        float(bernstein6_distance(t, dur, vs, ve)[0]), abs=1e-12 * (1.0 + max(vs, ve)))


def test_profile_rows_phases_and_chaining() -> None:
    """A profile is its rows: the phases as tuples are the same numbers, a profile built from
    them equals it, and sections chained by path_plan follow each other in time and arc length,
    each phase moved as the tuple-by-tuple chaining moved it (t0 + t - t_first, s0 + s - s_0)."""
    a, b = _plan_const(5.0, 0.0, 0.0), _plan_const(7.5, 0.0, 0.0)
    assert len(a) == len(a.phases) and np.array_equal(a.rows, np.array(a.phases))
    assert FeedProfile(a.phases) == a and FeedProfile(a.phases) != b
    assert len(FeedProfile()) == 0 and FeedProfile().duration_s == 0.0
    chained = _concat([a, b])
    expected = list(a.phases)
    t0, s0 = a.duration_s, a.length_mm
    expected += [FeedPhase(t0 + p.t0_s - b.t0_s, p.duration_s, s0 + p.s0_mm - b.phases[0].s0_mm,
                           p.v_start_mm_s, p.v_end_mm_s) for p in b.phases]
    assert chained.phases == tuple(expected)
    assert chained.duration_s == pytest.approx(a.duration_s + b.duration_s, abs=1e-15)
    assert chained.length_mm == pytest.approx(12.5, abs=1e-12)
