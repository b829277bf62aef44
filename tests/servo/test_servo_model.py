"""The numpy-only servo model against scipy.signal and the check values of
docs/algorithms.md, The servo model (eq. 27)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import cont2discrete, lfilter

from controller.config import load_config
from controller.servo.model import (
    AxisServoStepper,
    discretise,
    error_transfer,
    tracking_error_mm,
)

CFG = load_config()
T = CFG.sample_period_s


@pytest.mark.parametrize("axis", ["x", "y"])
def test_zoh_matches_scipy(axis: str) -> None:
    p = CFG.axis(axis).servo
    num, den = error_transfer(p)
    b_ref, a_ref, _ = cont2discrete((num, den), T, method="zoh")
    s = discretise(p, T)
    assert np.allclose(s.a, a_ref / a_ref[0], rtol=1e-9, atol=1e-14)
    assert np.allclose(s.b, np.squeeze(b_ref) / a_ref[0], rtol=1e-9, atol=1e-14)


def test_check_values_of_the_servo_model() -> None:
    s = discretise(CFG.axis("x").servo, T)
    assert s.a == pytest.approx([1, -3.332194, 4.188233, -2.352050, 0.497380], abs=1e-6)
    e = tracking_error_mm(s, np.full(400, 58.3333333))
    assert e.max() * 1000 == pytest.approx(198.0, abs=0.5)  # velocity-step transient
    assert e[-1] * 1000 == pytest.approx(18.66, abs=0.01)  # steady following error


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 2000), st.integers(0, 2**32 - 1), st.lists(st.integers(1, 700), max_size=6))
def test_filter_matches_lfilter_in_any_chunking(n: int, seed: int, cuts: list[int]) -> None:
    s = discretise(CFG.axis("y").servo, T)
    v = np.random.default_rng(seed).normal(0, 50, n)
    ref = lfilter(s.b, s.a, v)
    assert np.allclose(tracking_error_mm(s, v), ref, rtol=0, atol=1e-9)
    stepper = AxisServoStepper(s)
    edges = np.unique(np.clip(np.cumsum([0, *cuts, n]), 0, n))
    parts = [stepper.step(v[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    assert np.allclose(np.concatenate(parts), ref, rtol=0, atol=1e-9)
