"""Corners inside a NURBS: found at the knots where the tangent jumps, split there exactly."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.geometry.nurbs import Nurbs
from controller.geometry.nurbs_split import kink_knots, split_at
from controller.geometry.path import PieceKind, end_tangent, make_piece


@st.composite
def nurbs(draw: st.DrawFn) -> Nurbs:
    degree = draw(st.integers(1, 5))
    n = draw(st.integers(degree + 1, degree + 8))
    inner = sorted(draw(st.lists(st.floats(0.01, 0.99), min_size=n - degree - 1,
                                 max_size=n - degree - 1)))
    # At most `degree` copies of a knot: more breaks the curve (the interpreter refuses it).
    # Bumped in order, each past the one before, so a bump never makes a later run longer
    # (0.5 five times at degree 2 once gave 0.5, 0.5, 0.5, 0.505, 0.51: a broken curve).
    for i in range(len(inner)):
        inner[i] = max(inner[i], inner[i - 1]) if i else inner[i]
        if i >= degree and inner[i] == inner[i - degree]:
            inner[i] = inner[i - 1] + 0.001  # at most 7 bumps: stays under 1
    knots = np.concatenate((np.zeros(degree + 1), inner, np.ones(degree + 1)))
    points = np.array(draw(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)),
                                    min_size=n, max_size=n)))
    weights = np.array(draw(st.lists(st.floats(0.1, 10), min_size=n, max_size=n)))
    return Nurbs(degree, knots, points, weights)


@settings(max_examples=300, deadline=None)
@given(nurbs(), st.floats(0.02, 0.98))
def test_both_parts_are_the_curve(curve: Nurbs, u: float) -> None:
    (lk, lp, lw), (rk, rp, rw) = split_at(curve.degree, curve.knots, curve.control_points,
                                          curve.weights, u)
    left, right = Nurbs(curve.degree, lk, lp, lw), Nurbs(curve.degree, rk, rp, rw)
    scale = 1.0 + float(np.abs(curve.control_points).max())
    for part, lo, hi in ((left, 0.0, u), (right, u, 1.0)):
        t = np.linspace(lo, hi, 41)
        assert np.abs(part.evaluate(t, 0)[0] - curve.evaluate(t, 0)[0]).max() <= 1e-9 * scale
        assert (part.u_start, part.u_end) == (lo, hi)
    assert np.array_equal(lp[-1], rp[0])  # they meet at one point
    assert np.all(lw > 0) and np.all(rw > 0)


def _poly_line(points: list[tuple[float, float]]) -> Nurbs:
    """Degree 1 (G5.2 L2): a polyline, a corner at every inner point."""
    n = len(points)
    knots = np.concatenate(([0.0, 0.0], np.arange(1, n - 1, dtype=float), [n - 1.0] * 2))
    return Nurbs(1, knots, np.array(points, float), np.ones(n))


def test_a_polyline_turns_at_every_inner_point() -> None:
    square = _poly_line([(0, 0), (20, 0), (20, 20), (0, 20), (0, 0)])
    assert kink_knots(square) == [1.0, 2.0, 3.0]
    straight = _poly_line([(0, 0), (5, 0), (10, 0)])
    assert kink_knots(straight) == []


def test_a_cusp_is_a_corner_and_each_side_points_the_way_it_travels() -> None:
    cusp = Nurbs(2, np.array([0, 0, 0, 1, 2, 2, 2.0]),
                 np.array([[0, 0], [10, 0], [10, 0], [0, 0.0]]), np.ones(4))
    assert kink_knots(cusp) == [1.0]
    (lk, lp, lw), (rk, rp, rw) = split_at(2, cusp.knots, cusp.control_points, cusp.weights, 1.0)
    left, right = Nurbs(2, lk, lp, lw), Nurbs(2, rk, rp, rw)
    a = make_piece(PieceKind.NURBS, left, 0.0, 1.0, 0.0, 10.0, 3)
    b = make_piece(PieceKind.NURBS, right, 1.0, 2.0, 0.0, 10.0, 3)
    assert np.allclose(end_tangent(a, True), [1.0, 0.0])  # arriving: +X, not a zero vector
    assert np.allclose(end_tangent(b, False), [-1.0, 0.0])  # leaving: back along -X


@settings(max_examples=100, deadline=None)
@given(nurbs())
def test_a_smooth_curve_has_no_corner(curve: Nurbs) -> None:
    if curve.degree < 3 or len(np.unique(curve.knots)) != len(curve.knots) - 2 * curve.degree:
        return  # lower degrees and repeated inner knots may have true corners
    inner = np.unique(curve.knots)[1:-1]
    d1 = curve.evaluate(inner, 1)[1]
    if inner.size and np.hypot(d1[:, 0], d1[:, 1]).min() < 1e-3:
        return  # a vanishing derivative may be a cusp
    assert kink_knots(curve) == []


# From the adversarial run (g62_080): weights 0.001-1, a last knot span of 1e-4 next to 1s.
NARROW_SPAN = """G21 G90 G0 X143.690787 Y9.837479 G61 F3500
G6.2 P5 X143.690787 Y9.837479 R0.01 K0
X143.747223 Y15.027096 R0.01 K0
X148.4151 Y147.841871 R0.5 K0
X149.285407 Y131.492565 R0.01 K0
X140.543897 Y-77.609805 R0.001 K0
X149.46017 Y18.860643 R0.001 K1
X141.447411 Y36.380404 R0.5 K2
X149.354404 Y-80.626283 R1 K3
X143.533404 Y-98.09482 R0.001 K4
X149.77027 Y-88.824279 R0.001 K5
X142.584995 Y-126.287635 R0.001 K6
X141.014505 Y-145.23897 R1 K7
X140.039769 Y8.225844 R0.001 K8
X142.977382 Y-39.678773 R0.01 K9
X145.792628 Y-55.551972 R0.01 K10
X147.415027 Y-76.959317 R0.5 K11
X144.970273 Y-39.116982 R0.001 K12
K12.0001
K12.0001
K12.0001
K12.0001
K12.0001
"""


def test_a_narrow_knot_span_keeps_the_inverse_bounded_and_exact(tmp_path) -> None:  # noqa: ANN001
    """The arc-length inverse split this curve's sub-intervals by up to 64 a pass: 489,533
    rows (1 GB for the whole simulate). Past MAX_ROWS the rest is kept unchecked and inverted
    by Newton instead, as accurately."""
    from controller.interpreter.program import program_nurbs

    path = tmp_path / "narrow.nc"
    path.write_text(NARROW_SPAN)
    table = program_nurbs(str(path))[0].arc_length_table
    s = np.linspace(0.0, table.total_length_mm, 20001)
    u = table.u_of_s(s)
    assert table._inverse.rows.shape[0] <= 60_000  # MAX_ROWS and the base intervals
    assert np.abs(table.s_of_u(u) - s).max() < 1e-5
