"""NURBS evaluation, curvature and arc length against SciPy, geomdl and exact circles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geomdl import NURBS as GEOMDL
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.interpolate import BSpline

from controller.geometry.curves import ArcCurve, LineCurve
from controller.geometry.nurbs import Nurbs


@st.composite
def random_nurbs(draw: st.DrawFn) -> Nurbs:
    p = draw(st.integers(1, 5))
    n = draw(st.integers(p + 1, p + 8))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    inner = np.sort(rng.random(n - p - 1))
    if inner.size >= 2 and draw(st.booleans()):
        inner[1] = inner[0]  # a double knot: lower continuity inside
    knots = np.concatenate((np.zeros(p + 1), inner, np.ones(p + 1))) * 7.0 + 2.0
    # Weights all 1 (a polynomial B-spline, as most CAM output) take evaluation's shortcut.
    weights = np.ones(n) if draw(st.booleans()) else rng.uniform(0.2, 5.0, n)
    return Nurbs(p, knots, rng.uniform(-50, 50, (n, 2)), weights)


def scipy_rational(c: Nurbs, u: np.ndarray, order: int) -> np.ndarray:
    """Oracle: SciPy BSpline on homogeneous points, then the Leibniz quotient rule; on the
    points alone when every weight is 1 (the quotient rule would leave SciPy's round-off on
    w' = 0 where the derivative is exactly 0, above the degree)."""
    if np.all(c.weights == 1.0):
        b = BSpline(c.knots, c.control_points, c.degree)
        return np.array([b(u, nu=k) if k <= c.degree else np.zeros((u.size, 2))
                         for k in range(order + 1)])
    b = BSpline(c.knots, np.column_stack((c.control_points * c.weights[:, None], c.weights)),
                c.degree)
    a = [b(u)] + [b(u, nu=k) if k <= c.degree else np.zeros((u.size, 3))
                  for k in range(1, order + 1)]
    out: list[np.ndarray] = []
    for k in range(order + 1):
        acc = a[k][:, :2].copy()
        for i in range(1, k + 1):
            acc -= math.comb(k, i) * a[i][:, 2:3] * out[k - i]
        out.append(acc / a[0][:, 2:3])
    return np.array(out)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@settings(max_examples=40, deadline=None)
@given(random_nurbs(), st.integers(0, 3))
def test_evaluate_matches_scipy(c: Nurbs, order: int) -> None:
    u = np.concatenate((np.linspace(c.u_start, c.u_end, 41), c.knots[c.degree:-c.degree]))
    ours, ref = c.evaluate(u, order), scipy_rational(c, u, order)
    for k in range(order + 1):
        assert rel_err(ours[k], ref[k]) < 1e-12


@settings(max_examples=20, deadline=None)
@given(random_nurbs(), st.integers(0, 4))
def test_homogeneous_derivatives_match_de_boor(c: Nurbs, order: int) -> None:
    u = np.concatenate((np.linspace(c.u_start, c.u_end, 23), c.knots[c.degree:-c.degree]))
    ours, ref = c.homogeneous_derivatives(u, order), c.de_boor_derivatives(u, order)
    assert ours.shape == ref.shape == (order + 1, u.size, 3)
    assert rel_err(ours, ref) < 1e-12


@settings(max_examples=25, deadline=None)
@given(random_nurbs())
def test_evaluate_matches_geomdl(c: Nurbs) -> None:
    g = GEOMDL.Curve(normalize_kv=False)
    g.degree = c.degree
    g.ctrlpts = c.control_points.tolist()
    g.weights = c.weights.tolist()
    g.knotvector = c.knots.tolist()
    order = min(2, c.degree)
    for u in np.linspace(c.u_start, c.u_end, 9):
        ref = np.array(g.derivatives(float(u), order=order))
        assert rel_err(c.evaluate(u, order)[:, 0], ref) < 1e-12


@settings(max_examples=25, deadline=None)
@given(random_nurbs())
def test_scalar_path_matches_vectorised(c: Nurbs) -> None:
    for u in np.linspace(c.u_start, c.u_end, 13):
        d = c.evaluate(u, 2)[1:, 0].ravel()
        assert rel_err(np.array(c.derivatives_scalar(float(u))), d) < 1e-9


@settings(max_examples=15, deadline=None)
@given(random_nurbs())
def test_arc_length_and_inverse(c: Nurbs) -> None:
    u = np.linspace(c.u_start, c.u_end, 7)
    spans = np.unique(c.knots)
    ref = [sum(quad(lambda x: float(c.speed(np.array([x]))[0]), a, min(b, ui),
                    epsabs=0, epsrel=1e-13, limit=200)[0]
               for a, b in zip(spans[:-1], spans[1:], strict=True) if a < ui) for ui in u]
    assert rel_err(c.s_of_u(u), np.array(ref)) < 1e-9
    s = np.linspace(0.0, c.length_mm, 50)
    assert np.abs(c.s_of_u(c.u_of_s(s)) - s).max() < 1e-9 * c.length_mm


@settings(max_examples=15, deadline=None)
@given(random_nurbs(), st.floats(0.0, 1.0))
def test_scalar_inverse_without_the_inverse_table(c: Nurbs, share: float) -> None:
    """u_of_s_scalar (a windowed blend's cut): the arc length it lands on is the one asked
    for, and no inverse table is built for it."""
    table = c.arc_length_table
    s = share * c.length_mm
    u = table.u_of_s_scalar(s, c.u_start, c.u_end, 1e-10)
    assert c.u_start <= u <= c.u_end
    assert abs(float(c.s_of_u(np.array([u]))[0]) - s) <= 1e-10 + 1e-12 * c.length_mm
    assert "_inverse" not in vars(table)


@settings(max_examples=25, deadline=None)
@given(random_nurbs(), st.integers(0, 2**32 - 1))
def test_small_arrays_remembered_give_the_numbers_of_a_fresh_call(c: Nurbs, seed: int) -> None:
    """evaluate and s_of_u on a few parameters are remembered by value (an interned curve is
    asked the same points on every copy of a long program): asked again, in any order, with
    any derivative order, they give the numbers of a curve that never remembered them, and
    each answer is a copy of its own."""
    import controller.geometry.nurbs as nurbs_module

    rng = np.random.default_rng(seed)
    fresh = Nurbs(c.degree, c.knots.copy(), c.control_points.copy(), c.weights.copy())
    asks = [(rng.uniform(c.u_start, c.u_end, rng.integers(1, 5)), int(rng.integers(-1, 4)))
            for _ in range(6)]
    for u, order in asks + asks[::-1] + asks:
        got = c.s_of_u(u) if order < 0 else c.evaluate(u, order)
        ref = fresh.arc_length_table.s_of_u(u) if order < 0 else fresh._evaluate(u, order)
        assert np.array_equal(got, ref)
        got += 1.0  # the caller's own array: the next answer is untouched
    big = np.linspace(c.u_start, c.u_end, nurbs_module.MEMO_POINTS + 1)
    assert np.array_equal(c.evaluate(big, 2), fresh._evaluate(big, 2))
    assert len(c._memo) <= 2 * len(asks)  # the large array was not remembered
    for k in range(nurbs_module.MEMO_ENTRIES + 5):
        c.evaluate(np.array([c.u_start + (c.u_end - c.u_start) * k / 1000.0]), 1)
    assert len(c._memo) <= nurbs_module.MEMO_ENTRIES


@settings(max_examples=25, deadline=None)
@given(random_nurbs())
def test_rows_and_the_joint_curvature_give_the_numbers_of_evaluate(c: Nurbs) -> None:
    """evaluate_rows is evaluate's array with x and y as rows, and the corner detector's
    curvature with its slope from those rows equals the two (N, 2) functions bit for bit."""
    from controller.geometry.curves import (
        curvature_and_derivative_from_rows,
        curvature_derivative_from_derivatives,
        curvature_from_derivatives,
    )

    u = np.concatenate((np.linspace(c.u_start, c.u_end, 301), c.knots[c.degree : -c.degree]))
    rows = c.evaluate_rows(u, 3)
    d = c.evaluate(u, 3)
    assert np.array_equal(rows.transpose(0, 2, 1), d)
    kappa, slope = curvature_and_derivative_from_rows(rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        assert np.array_equal(kappa, curvature_from_derivatives(d), equal_nan=True)
        assert np.array_equal(slope, curvature_derivative_from_derivatives(d), equal_nan=True)


def quarter_circle(radius: float) -> Nurbs:
    """Exact rational quadratic quarter circle: kappa = 1/R everywhere."""
    pts = np.array([[radius, 0.0], [radius, radius], [0.0, radius]])
    return Nurbs(2, np.array([0.0, 0, 0, 1, 1, 1]), pts, np.array([1.0, math.sqrt(0.5), 1.0]))


@pytest.mark.parametrize("radius", [0.1, 3.0, 250.0])
def test_rational_circle_curvature_and_length(radius: float) -> None:
    c = quarter_circle(radius)
    u = np.linspace(0, 1, 101)
    assert np.abs(np.linalg.norm(c.evaluate(u, 0)[0], axis=1) - radius).max() < 1e-12 * radius
    assert np.abs(c.curvature(u) * radius - 1.0).max() < 1e-12
    assert np.abs(c.curvature_derivative(u)).max() * radius < 1e-9
    assert c.length_mm == pytest.approx(math.pi * radius / 2, rel=1e-12)


@settings(max_examples=20, deadline=None)
@given(random_nurbs())
def test_curvature_derivative_is_derivative(c: Nurbs) -> None:
    spans = np.unique(c.knots)
    a, b = spans[0], spans[1]  # inside one span, kappa is smooth away from inflections
    u = a + (b - a) * np.array([0.3, 0.5, 0.7])
    h = (b - a) * 1e-6
    fd = (c.curvature(u + h) - c.curvature(u - h)) / (2 * h)
    dk = c.curvature_derivative(u)
    ok = np.abs(dk - fd) <= 1e-4 * (np.abs(fd) + c.curvature(u) / (b - a)) + 1e-9
    inflection = c.curvature(u) < 1e-6 * (1 + np.abs(fd) * (b - a))
    assert np.all(ok | inflection)


def test_line_and_arc_curves() -> None:
    line = LineCurve((1.0, 2.0), (4.0, 6.0))
    assert line.length_mm == 5.0
    np.testing.assert_allclose(line.evaluate([0.5], 2)[:, 0], [[2.5, 4.0], [3.0, 4.0], [0, 0]])
    assert line.u_of_s([2.5])[0] == 0.5
    arc = ArcCurve((1.0, -1.0), 2.0, 0.3, -2.5)
    u = np.linspace(0, 1, 11)
    d = arc.evaluate(u, 3)
    assert np.abs(np.linalg.norm(d[0] - (1.0, -1.0), axis=1) - 2.0).max() < 1e-14
    h = 1e-6
    for k in range(3):
        fd = (arc.evaluate(u + h, k)[k] - arc.evaluate(u - h, k)[k]) / (2 * h)
        np.testing.assert_allclose(d[k + 1], fd, atol=1e-6 * 2.5 ** (k + 2))
    np.testing.assert_allclose(arc.curvature(u), 0.5)
    np.testing.assert_allclose(arc.derivatives_scalar(0.4), d[1:3, 4].ravel(), atol=1e-14)
    assert arc.length_mm == pytest.approx(5.0)


def test_all_curves_offer_the_curve_protocol() -> None:
    from controller.geometry.curves import Curve
    from controller.geometry.ph_quintic import PhQuintic

    for c in (quarter_circle(1.0), LineCurve((0, 0), (1, 0)), ArcCurve((0, 0), 1, 0, 1),
              PhQuintic.hermite(0, 1, 1, 1)):
        assert isinstance(c, Curve)
        u = np.array([0.25, 0.75])
        assert c.evaluate(u, 3).shape == (4, 2, 2)
        np.testing.assert_allclose(c.u_of_s(c.s_of_u(u)), u, atol=1e-12)
        assert c.s_of_u(np.array([c.u_end]))[0] == pytest.approx(c.length_mm, rel=1e-12)


def _quintic_expression(x, h, u0, u1, d0, c0, d1, c1):  # type: ignore[no-untyped-def]
    """The inverse table's quintic Hermite as one expression: the reference."""
    x2 = x * x
    x3 = x2 * x
    m = 1 - x
    m2 = m * m
    m3 = m2 * m
    return (m3 * (1 + 3 * x + 6 * x2) * u0 + x3 * (1 + 3 * m + 6 * m2) * u1
            + h * (m3 * x * (1 + 3 * x) * d0 - x3 * m * (1 + 3 * m) * d1)
            + 0.5 * h * h * (m3 * x2 * c0 + x3 * m2 * c1))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 3000))
def test_inverse_quintic_in_place_equals_the_expression(seed: int, n: int) -> None:
    """u(s) between the inverse table's nodes, computed in place, is the expression's number
    bit for bit (values, slopes and curvatures of any size, x on [0, 1] with its ends)."""
    from controller.geometry.arclength_inverse import _quintic

    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 1.0, n)
    x[: min(n, 2)] = (0.0, 1.0)[: min(n, 2)]
    args = [x] + [rng.normal(size=n) * 10.0 ** rng.uniform(-8, 4) for _ in range(7)]
    assert np.array_equal(_quintic(*args), _quintic_expression(*args))


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # quad at 1e-13
def test_arc_length_through_a_near_cusp_is_as_accurate_as_elsewhere() -> None:
    # Hypothesis found this curve: its speed dips to 1.4e-4 mm per unit of u at u = 3.3641
    # (a kink in |C'|), where uniform doubling of the Gauss-Legendre intervals stopped at its
    # cap 3.5e-7 mm off; the intervals there are now halved until they agree.
    c = Nurbs(
        degree=4,
        knots=np.array([2.0] * 5 + [4.332801551874313, 5.005587303914631] + [9.0] * 5),
        control_points=np.array([
            [34.95207620282764, -43.69845596185681], [-7.460354116012638, 14.186447890826386],
            [-37.92223079602945, -37.92272382858755], [49.585154833351396, 43.46655579413773],
            [-7.9703482286398994, 22.28142621350419], [6.616998203013111, 35.06837935916208],
            [-47.49551966421581, 26.675255211870265]]),
        weights=np.ones(7),
    )
    cusp_u, end_u = 3.364102040086681, 4.332801551874313

    def speed(x: float) -> float:
        return float(c.speed(np.array([x]))[0])

    want = sum(quad(speed, a, b, epsabs=0, epsrel=1e-13, limit=500)[0]
               for a, b in ((2.0, cusp_u), (cusp_u, end_u)))
    assert abs(float(c.s_of_u(np.array([end_u]))[0]) - want) < 1e-9 * want
