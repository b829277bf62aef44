"""PH quintic Hermite interpolation: the worked checks of docs/algorithms.md (PH quintic
blends) and closed-form identities."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from controller.geometry.ph_quintic import PhQuintic, _candidates

CALGO = (0.8 + 1.4j, 2.4 + 0.8j, 2.6 + 4.2j, 4.2 + 3.6j)  # p0, p1, p4, p5


def calgo() -> PhQuintic:
    p0, p1, p4, p5 = CALGO
    return PhQuintic.hermite(p0, p5, 5 * (p1 - p0), 5 * (p5 - p4))


def test_straight_line_is_uniform_speed() -> None:
    ph = PhQuintic.hermite(0, 1, 1, 1)
    assert (ph.w0, ph.w1, ph.w2) == (1, 1, 1)
    np.testing.assert_allclose(ph.control_points(), [0, 0.2, 0.4, 0.6, 0.8, 1.0], atol=1e-15)
    xi = np.linspace(0, 1, 11)
    np.testing.assert_allclose(ph.arc_length(xi), xi, atol=1e-15)
    others = sorted((c.w1 / c.w0).real for c in _candidates(0j, 1 + 0j, 1 + 0j, 1 + 0j)[1:])
    assert others == pytest.approx(sorted([-4.0, math.sqrt(5), -math.sqrt(5)]))


def test_calgo_example() -> None:
    ph = calgo()
    cp = ph.control_points()
    assert cp[[0, 1, 4, 5]] == pytest.approx(np.array(CALGO), abs=1e-12)
    assert cp[2] == pytest.approx(2.837719 + 2.514034j, abs=1e-6)
    assert cp[3] == pytest.approx(2.162281 + 2.485966j, abs=1e-6)
    assert ph.bending_energy() == pytest.approx(2.825699, abs=1e-6)
    assert ph.absolute_rotation_index() == min(
        c.absolute_rotation_index() for c in _candidates(CALGO[0], CALGO[3] - CALGO[0],
                                                         5 * (CALGO[1] - CALGO[0]),
                                                         5 * (CALGO[3] - CALGO[2])))


def test_quarter_circle() -> None:
    ph = PhQuintic.hermite(1, 1j, 1j * math.pi / 2, -math.pi / 2)
    np.testing.assert_allclose(ph.sigma_bernstein,
                               [1.570796, 1.558864, 1.578540, 1.558864, 1.570796], atol=1e-6)
    assert ph.length_mm == pytest.approx(1.567572, abs=1e-6)
    xi = np.linspace(0, 1, 2001)
    assert np.abs(np.abs(ph.point(xi)) - 1).max() == pytest.approx(3.9e-3, abs=1e-4)
    assert ph.absolute_rotation_index() == pytest.approx(0.25, abs=1e-12)


hermite_data = st.tuples(*[st.complex_numbers(max_magnitude=20, min_magnitude=0.5,
                                              allow_nan=False, allow_infinity=False)] * 4)


@settings(max_examples=60, deadline=None)
@given(hermite_data)
def test_hermite_interpolates_and_closed_forms_hold(data: tuple[complex, ...]) -> None:
    p0, dp, d0, d1 = data
    ph = PhQuintic.hermite(p0, p0 + dp, d0, d1)
    scale = max(abs(dp), abs(d0), abs(d1))
    assert abs(ph.point(0.0)[0] - p0) < 1e-12 * scale + 1e-12 * abs(p0)
    assert abs(ph.point(1.0)[0] - (p0 + dp)) < 1e-11 * scale + 1e-12 * abs(p0)
    assert abs(ph.hodograph(0.0)[0] - d0) < 1e-12 * scale
    assert abs(ph.hodograph(1.0)[0] - d1) < 1e-12 * scale
    xi = np.linspace(0, 1, 9)
    np.testing.assert_allclose(ph.sigma(xi), np.abs(ph.hodograph(xi)), rtol=1e-12,
                               atol=1e-13 * scale)
    ref = [quad(lambda x: abs(ph.hodograph(x)[0]), 0, b, epsabs=0, epsrel=1e-13)[0] for b in xi]
    assert np.abs(ph.arc_length(xi) - ref).max() <= 1e-12 * max(ph.length_mm, 1.0)
    assert ph.arc_length(1.0)[0] == pytest.approx(ph.length_mm, rel=1e-13)
    # the chosen one has the smallest absolute rotation index of the four
    best = min(c.absolute_rotation_index() for c in _candidates(p0, dp, d0, d1))
    assert ph.absolute_rotation_index() <= best + 1e-9


@settings(max_examples=30, deadline=None)
@given(hermite_data)
def test_derivatives_and_curvature(data: tuple[complex, ...]) -> None:
    p0, dp, d0, d1 = data
    ph = PhQuintic.hermite(p0, p0 + dp, d0, d1)
    xi, h = np.array([0.2, 0.5, 0.8]), 1e-6
    scale = max(abs(dp), abs(d0), abs(d1))
    for f, df in ((ph.point, ph.hodograph), (ph.hodograph, ph.second_derivative),
                  (ph.second_derivative, ph.third_derivative)):
        fd = (f(xi + h) - f(xi - h)) / (2 * h)
        assert np.abs(fd - df(xi)).max() < 1e-6 * scale * 100
    d = ph.evaluate(xi, 2)
    cross = d[1, :, 0] * d[2, :, 1] - d[1, :, 1] * d[2, :, 0]
    # atol: a straight-line PH has curvature 0 up to roundoff (1e-16 /mm), where rtol means nothing
    np.testing.assert_allclose(ph.curvature(xi),
                               np.abs(cross) / np.hypot(d[1, :, 0], d[1, :, 1]) ** 3, rtol=1e-9,
                               atol=1e-12 / scale)


def test_rotation_index_of_cusp_and_s_shapes() -> None:
    # collinear candidates with zero-speed points do not turn; a mild S turns under half a turn
    loop = min(_candidates(0j, 1 + 0j, 1 + 0j, 1 + 0j)[1:], key=lambda c: c.bending_energy())
    assert loop.absolute_rotation_index() == pytest.approx(0.0, abs=1e-12)  # collinear cusps
    s = PhQuintic.hermite(0, 1, 3 * cmath.exp(1j), 3 * cmath.exp(-1j))
    assert s.absolute_rotation_index() < 0.5


@settings(max_examples=300, deadline=None)
@given(st.floats(-1.39, 1.39), st.floats(-1.39, 1.39), st.floats(0.5, 2.0), st.floats(0.5, 2.0))
def test_tame_data_fast_path_picks_the_best_of_the_four(a0: float, a1: float, m0: float,
                                                        m1: float) -> None:
    """Tangents within 80 degrees of the chord, 0.5-2 chords long: (+,+) is the best."""
    import cmath

    d0, d1 = m0 * cmath.exp(1j * a0), m1 * cmath.exp(1j * a1)
    ph = PhQuintic.hermite(0j, 1 + 0j, d0, d1)
    ranked = min(_candidates(0j, 1 + 0j, d0, d1),
                 key=lambda c: (round(c.absolute_rotation_index(), 9),
                                round(c.bending_energy(), 9)))
    assert ph.absolute_rotation_index() <= ranked.absolute_rotation_index() + 1e-9
    assert ph.bending_energy() <= ranked.bending_energy() * (1 + 1e-9)


_coef = st.one_of(st.just(0j), st.complex_numbers(min_magnitude=1e-3, max_magnitude=1e3,
                                                  allow_nan=False, allow_infinity=False))


@settings(max_examples=200, deadline=None)
@given(_coef, _coef, _coef)
def test_quadratic_roots_match_numpy(a: complex, b: complex, c: complex) -> None:
    """The closed-form roots used for the rotation index are np.roots' (as a set)."""
    from controller.geometry.ph_quintic import _quadratic_roots

    ours = _quadratic_roots(a, b, c)
    if a == 0 and b == 0:
        assert ours == []
        return
    ref = np.roots([a, b, c]) if a != 0 else np.roots([b, c])
    assert len(ours) == len(ref)
    scale = max(1.0, *(abs(z) for z in ref))
    for z in ours:  # each of ours is a root of numpy's within round-off
        assert min(abs(z - r) for r in ref) <= 1e-6 * scale
    for z in ref:
        assert min(abs(z - r) for r in ours) <= 1e-6 * scale
