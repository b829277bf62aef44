"""Helices and arcs in the three planes as 3-D curves: exact length, derivatives, curvature,
box and distance, against dense sampling and finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.blocks import HelixBlock, PathControl, Source
from controller.geometry.helix import HelixCurve
from controller.numeric import segment_distance

PROPS = settings(max_examples=80, deadline=None)
planes = st.sampled_from(["G17", "G18", "G19"])
sweeps = st.floats(-4 * math.pi, 4 * math.pi).filter(lambda s: abs(s) > 1e-3)


def helices():
    return st.builds(HelixCurve, planes, st.tuples(st.floats(-50, 50), st.floats(-50, 50)),
                     st.floats(0.1, 40), st.floats(-math.pi, math.pi), sweeps,
                     st.floats(-20, 20), st.floats(-30, 30))


def dense(curve: HelixCurve, n: int = 200_001) -> np.ndarray:
    return curve.points(np.linspace(0.0, 1.0, n))


@PROPS
@given(helices())
def test_length_is_the_unrolled_hypotenuse(curve: HelixCurve) -> None:
    pts = dense(curve)
    polyline = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    assert curve.length_mm == pytest.approx(polyline, rel=1e-8, abs=1e-9)
    assert curve.length_mm >= polyline * (1 - 1e-12)  # a chord is never longer than its arc


@PROPS
@given(helices(), st.floats(0.01, 0.99))
def test_derivatives_and_curvature(curve: HelixCurve, u: float) -> None:
    h = 1e-5
    d = curve.evaluate([u], 2)[:, 0]
    p_minus, p_plus = curve.points([u - h])[0], curve.points([u + h])[0]
    scale = 1 + curve.radius * abs(curve.sweep) ** 2 + abs(curve.rise)
    assert np.allclose(d[1], (p_plus - p_minus) / (2 * h), atol=1e-6 * scale)
    assert np.allclose(d[2], (p_plus - 2 * d[0] + p_minus) / h**2, atol=1e-3 * scale)
    kappa = np.linalg.norm(np.cross(d[1], d[2])) / np.linalg.norm(d[1]) ** 3
    assert curve.curvature_per_mm == pytest.approx(kappa, rel=1e-9)
    pitch = curve.rise / curve.sweep  # rise per radian
    assert curve.curvature_per_mm == pytest.approx(curve.radius / (curve.radius**2 + pitch**2))


@PROPS
@given(helices())
def test_box_is_the_tight_box(curve: HelixCurve) -> None:
    pts = dense(curve, 40_001)
    lo, hi = np.array(curve.box()[0]), np.array(curve.box()[1])
    tol = 1e-9 * (1 + np.abs(pts).max())
    assert np.all(pts.min(axis=0) >= lo - tol) and np.all(pts.max(axis=0) <= hi + tol)
    slack = curve.radius * (1 - math.cos(abs(curve.sweep) / 40_000)) + tol
    assert np.all(pts.min(axis=0) <= lo + slack) and np.all(pts.max(axis=0) >= hi - slack)


@PROPS
@given(helices(), st.lists(st.tuples(st.floats(0, 1), st.floats(-1, 1), st.floats(-1, 1),
                                     st.floats(-1, 1)), min_size=1, max_size=8),
       st.floats(1e-4, 0.05))
def test_distance_of_points_near_the_curve(curve: HelixCurve, offsets: list, size_mm: float
                                           ) -> None:
    """Points within size_mm of the curve, started from a parameter that is off by as much
    as a tool lagging its reference is (40 times its distance, at most 0.9 rad of turn): the
    distance is that of the dense polyline near it
    (a quarter turn each side; another turn of the helix may pass closer, and is not its
    path there)."""
    u = np.array([o[0] for o in offsets])
    p = curve.points(u) + size_mm * np.array([o[1:] for o in offsets])
    lag = np.clip(u - min(40 * size_mm / max(curve.length_mm, 1e-9),  # a lag of 40 sizes,
                          0.9 / abs(curve.sweep)), 0, 1)  # within the search's turn
    got = curve.distance_mm(p, lag)
    grid = np.linspace(0.0, 1.0, 100_001)
    pts = curve.points(grid)
    near = (math.pi / 2) / abs(curve.sweep)
    want = []
    for q, ui in zip(p, u, strict=True):
        k = np.flatnonzero(np.abs(grid - ui) <= near)
        k = k[:-1] if k[-1] == len(grid) - 1 else k
        want.append(segment_distance(q[None, :], pts[k], pts[k + 1]).min())
    chord = curve.radius * (1 - math.cos(abs(curve.sweep) / 200_000))
    assert np.all(got <= np.array(want) + 1e-9 + chord)
    assert np.all(got >= np.array(want) - 1e-9 - chord)


def _block(plane: str, start: tuple, end: tuple, center: tuple, clockwise: bool,
           turns: int = 0) -> HelixBlock:
    return HelixBlock(plane, start, end, center, clockwise, turns, 10.0, PathControl(),
                      Source("p", 1, 1))


def test_planes_turn_counter_clockwise_about_their_normal() -> None:
    # G18's plane is (Z, X): counter-clockwise seen from +Y takes +Z towards +X
    g18 = HelixCurve.from_block(_block("G18", (0.0, 0.0, 5.0), (5.0, 0.0, 0.0), (0.0, 0.0),
                                       clockwise=False))
    assert g18.sweep == pytest.approx(math.pi / 2)
    mid = g18.points([0.5])[0]
    assert mid == pytest.approx([5 / math.sqrt(2), 0.0, 5 / math.sqrt(2)])
    # G19's plane is (Y, Z): counter-clockwise seen from +X takes +Y towards +Z
    g19 = HelixCurve.from_block(_block("G19", (0.0, 5.0, 0.0), (0.0, 0.0, 5.0), (0.0, 0.0),
                                       clockwise=False))
    assert g19.points([0.5])[0] == pytest.approx([0.0, 5 / math.sqrt(2), 5 / math.sqrt(2)])


def test_a_full_turn_helix_with_turns() -> None:
    block = _block("G17", (10.0, 0.0, 0.0), (10.0, 0.0, -3.0), (0.0, 0.0), clockwise=True,
                   turns=2)
    assert block.sweep_rad == pytest.approx(-6 * math.pi)
    assert block.length_mm == pytest.approx(math.hypot(60 * math.pi, 3.0))
    assert HelixCurve.from_block(block).points([1.0])[0] == pytest.approx([10.0, 0.0, -3.0])
