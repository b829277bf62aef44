"""Feed limits from curvature (eqs. 22-24 and the centripetal limit)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.generator.feed.limits import (
    centripetal_feed_mm_s,
    chord_error_feed_mm_s,
    corner_feed_mm_s,
    curvature_feed_mm_s,
    path_feed_limit_mm_s,
)

VMAX, AMAX, T, DELTA = 3500.0 / 60.0, 2450.0, 1e-3, 1e-3


def test_chord_error_feed_value() -> None:
    # kappa = 1/mm: chord 2 sqrt(2*1*0.001 - 1e-6) = 0.089437 mm per 1 ms sample.
    v = chord_error_feed_mm_s(np.array([1.0]), T, DELTA, 1e6)
    assert v[0] == pytest.approx(2.0 * np.sqrt(2e-3 - 1e-6) / T, rel=1e-12)


def test_chord_error_feed_limits() -> None:
    k = np.array([0.0, -0.0, 1e-12, 1.0 / DELTA, 2.0 / DELTA, 1e9])
    v = chord_error_feed_mm_s(k, T, DELTA, VMAX)
    assert np.all(np.isfinite(v)) and np.all(v >= 0.0)
    assert v[0] == v[1] == v[2] == VMAX
    uncapped = chord_error_feed_mm_s(k, T, DELTA, np.inf)
    # Continuous at rho = delta (chord = diameter), no NaN where 2 delta/kappa < delta^2.
    assert uncapped[3] == pytest.approx(2.0 * DELTA / T)
    assert uncapped[4] == pytest.approx(DELTA / T)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.0, 1e4), min_size=2, max_size=50))
def test_limits_monotone_in_curvature_and_capped(kappas: list[float]) -> None:
    k = np.sort(np.array(kappas))
    for v in (chord_error_feed_mm_s(k, T, DELTA, VMAX), curvature_feed_mm_s(k, 1.0, VMAX),
              centripetal_feed_mm_s(k, AMAX, VMAX), path_feed_limit_mm_s(k, T, DELTA, AMAX, VMAX),
              corner_feed_mm_s(k, T, DELTA, 1.0, VMAX)):
        assert np.all(v <= VMAX) and np.all(v > 0.0)
        assert np.all(np.diff(v) <= 1e-12)


def test_curvature_feed_eq24() -> None:
    v = curvature_feed_mm_s(np.array([0.0, 1.0, 3.0]), 1.0, VMAX)
    assert v == pytest.approx([VMAX, VMAX / 2.0, VMAX / 4.0])


def test_centripetal_feed_normal_accel() -> None:
    k = np.array([0.5, 1.3, 42.5])
    v = centripetal_feed_mm_s(k, AMAX, np.inf)
    assert k * v * v == pytest.approx(np.full(3, AMAX))
    assert centripetal_feed_mm_s(np.array([0.0]), AMAX, VMAX)[0] == VMAX
