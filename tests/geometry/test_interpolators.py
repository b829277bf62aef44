"""PH Newton interpolator (eq. 12), second-order Taylor interpolator (eq. 5), feed fluctuation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import read_program_nurbs

from controller.geometry.curves import ArcCurve, LineCurve
from controller.geometry.ph_interpolate import control_rows, ph_interpolate_many, power_forms
from controller.geometry.ph_quintic import NEWTON_TOL_MM, PhQuintic, ph_interpolate
from controller.geometry.taylor import feed_fluctuation, taylor_interpolate, taylor_step

cplx = st.complex_numbers(max_magnitude=50, min_magnitude=0.5, allow_nan=False,
                          allow_infinity=False)



@settings(max_examples=60, deadline=None)
@given(cplx, cplx, cplx, st.floats(0.05, 5.0))
def test_ph_newton_residual(dp: complex, d0: complex, d1: complex, step_mm: float) -> None:
    ph = PhQuintic.hermite(0j, dp, d0, d1)
    targets = np.arange(0.0, ph.length_mm, step_mm * ph.length_mm / 50)
    xi, residual = ph_interpolate(ph, targets)
    assert residual.max() < NEWTON_TOL_MM
    assert np.all(np.diff(xi) >= 0) and xi[0] == 0.0 and xi[-1] <= 1.0
    np.testing.assert_allclose(ph.arc_length(xi), targets, atol=NEWTON_TOL_MM)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(cplx, cplx, cplx), min_size=1, max_size=5), st.integers(0, 2**31))
def test_ph_interpolate_many_matches_one_at_a_time(data: list, seed: int) -> None:
    """Samples on several quintics at once: the same points and tangents as one at a time."""
    phs = [PhQuintic.hermite(0j, dp, d0, d1) for dp, d0, d1 in data]
    rng = np.random.default_rng(seed)
    which = rng.integers(0, len(phs), 200)
    s = rng.uniform(0.0, 1.0, 200) * np.array([ph.length_mm for ph in phs])[which]
    xy, phi = ph_interpolate_many(phs, which, s)
    for i, ph in enumerate(phs):
        rows = which == i
        xi, _ = ph_interpolate(ph, s[rows])
        d = ph.evaluate(xi, 1)
        np.testing.assert_allclose(xy[rows], d[0], atol=1e-9 * max(1.0, ph.length_mm))
        dphi = np.angle(np.exp(1j * (phi[rows] - np.arctan2(d[1, :, 1], d[1, :, 0]))))
        assert np.all(np.abs(dphi) < 1e-9)
        np.testing.assert_allclose(ph.arc_length(ph_interpolate(ph, s[rows])[0]), s[rows],
                                   atol=NEWTON_TOL_MM)


coefficient = st.one_of(st.sampled_from([0j, complex(-0.0, 1.0), complex(1.0, -0.0)]),
                        st.complex_numbers(max_magnitude=1e4, allow_nan=False,
                                           allow_infinity=False))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(coefficient, coefficient, coefficient, coefficient), min_size=1,
                max_size=30))
def test_control_rows_and_length_are_the_quintics_own_bit_for_bit(data: list) -> None:
    """control_rows (all quintics at once) gives each PhQuintic.control_points, and length_mm
    (Python floats) gives sigma_bernstein.sum() / 5, to the bit, signed zeros included."""
    z = np.array(data, complex).reshape(-1, 4)
    phs = [PhQuintic(*(complex(c) for c in row)) for row in z]
    rows = control_rows(z[:, 0], z[:, 1:])
    own = np.array([ph.control_points() for ph in phs])
    assert rows.view(np.uint64).tolist() == own.view(np.uint64).tolist()
    numpy_sum = np.array([ph.sigma_bernstein.sum() / 5.0 for ph in phs])
    lengths = np.array([ph.length_mm for ph in phs])
    assert lengths.view(np.uint64).tolist() == numpy_sum.view(np.uint64).tolist()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(cplx, cplx, cplx, cplx), min_size=1, max_size=40))
def test_power_forms_of_many_quintics_are_each_quintics_own(data: list) -> None:
    """The Newton iteration's coefficients, computed for all quintics at once, are each
    quintic's own cached ones bit for bit (so a run's samples are as before)."""
    phs = [PhQuintic.hermite(p0, p0 + dp, d0, d1) for p0, dp, d0, d1 in data]
    forms = power_forms(phs)
    np.testing.assert_array_equal(forms.s_power, [ph._s_power for ph in phs])
    np.testing.assert_array_equal(forms.sigma_power, [ph._sigma_power for ph in phs])
    np.testing.assert_array_equal(forms.r_power, [ph._r_power for ph in phs])
    np.testing.assert_array_equal(forms.table_s, [ph.arc_length_table[1] for ph in phs])


def test_ph_calgo_quintic_feed_ticks() -> None:
    """docs/algorithms.md (PH quintic blends): CALGO curve (4.82 mm), rest-to-rest feed, 1 ms."""
    ph = PhQuintic.hermite(0.8 + 1.4j, 4.2 + 3.6j, 5 * (1.6 - 0.6j), 5 * (1.6 - 0.6j))
    t = np.arange(0, 106) / 105  # normalised time; smooth F(t) from 0 to the full length
    f = ph.length_mm * (10 * t**3 - 15 * t**4 + 6 * t**5)
    xi, residual = ph_interpolate(ph, f)
    assert residual.max() < 1e-12
    assert xi[-1] == pytest.approx(1.0, abs=1e-12)


def test_taylor_exact_on_a_line() -> None:
    line = LineCurve((0.0, 0.0), (3.0, 4.0))
    u = taylor_interpolate(line, 0.0, np.full(100, 20.0), np.zeros(100), 1e-3)
    assert np.diff(u) == pytest.approx(np.full(100, 20.0e-3 / 5.0))
    assert taylor_step(line, 0.0, 0.0, 1000.0, 1e-3) == pytest.approx(0.5 * 1000 * 1e-6 / 5)


def test_taylor_on_an_arc_has_small_drift() -> None:
    arc = ArcCurve((0.0, 0.0), 10.0, 0.0, math.pi)
    v = 50.0
    u = taylor_interpolate(arc, 0.0, np.full(500, v), np.zeros(500), 1e-3)
    ff = feed_fluctuation(arc.s_of_u(u), v, 1e-3)  # constant |C'|: the step is exact
    assert ff.max_ratio < 1e-12


def test_taylor_fluctuation_on_butterfly_matches_reference_table() -> None:
    """docs/algorithms.md (PH quintic blends): Taylor at 58.33 mm/s: max ~110 %, RMS ~1.7e-2."""
    c = read_program_nurbs("butterfly.nc")
    v, period = 58.33, 1e-3
    n = int(c.length_mm / (v * period)) - 1
    u = taylor_interpolate(c, 0.0, np.full(n, v), np.zeros(n), period)
    ff = feed_fluctuation(c.s_of_u(u), v, period)
    assert 0.8 < ff.max_ratio < 1.5
    assert 0.01 < ff.rms_ratio < 0.025
    slow = taylor_interpolate(c, 0.0, np.full(3000, 10.0), np.zeros(3000), period)
    assert feed_fluctuation(c.s_of_u(slow), 10.0, period).max_ratio < 0.1


def test_feed_fluctuation_chord_and_arc_forms() -> None:
    s = np.array([0.0, 1.0, 2.1, 2.9])
    ff = feed_fluctuation(s, 1000.0, 1e-3)
    np.testing.assert_allclose(ff.per_step, [0.0, 0.1, 0.2])
    assert ff.max_ratio == pytest.approx(0.2)
    assert ff.rms_ratio == pytest.approx(math.sqrt(0.05 / 3))
    pts = np.array([[0.0, 0.0], [3.0, 4.0]])
    assert feed_fluctuation(pts, 5000.0, 1e-3).max_ratio == pytest.approx(0.0)
