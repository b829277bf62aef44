"""True contour error (path_distance): against brute force, and the cases eq. 28 cannot see."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from controller.blocks import NurbsBlock, StopBlock
from controller.config import load_config
from controller.geometry.nurbs import Nurbs
from controller.interpreter.program import read_program
from controller.servo.path_distance import (
    PathDistance,
    brute_force_distance_mm,
    path_distance,
    path_polyline,
)

REPO = Path(__file__).resolve().parents[2]
coord = st.floats(-50.0, 50.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(poly=arrays(float, st.tuples(st.integers(1, 40), st.just(2)), elements=coord),
       pts=arrays(float, st.tuples(st.integers(1, 60), st.just(2)), elements=coord))
def test_matches_brute_force_on_random_polylines(poly: np.ndarray, pts: np.ndarray) -> None:
    fp = path_distance(poly, pts)
    assert np.allclose(fp.distance_mm, brute_force_distance_mm(poly, pts), atol=1e-9, rtol=0)
    # The foot point is on the reported segment and at the reported distance.
    assert np.allclose(np.hypot(*(pts - fp.foot_mm).T), fp.distance_mm, atol=1e-9)
    assert np.all((fp.t >= 0) & (fp.t <= 1))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(2, 400),
       spread=st.floats(1e-4, 5.0))
def test_matches_brute_force_on_dense_wiggly_paths(seed: int, n: int, spread: float) -> None:
    """Dense paths with very uneven segment lengths (short steps and long jumps) and points at
    all distances: the k-nearest widening must still find the true nearest segment."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(0, 1, (n, 2)) * np.where(rng.random(n) < 0.1, 10.0, 0.01)[:, None]
    poly = np.cumsum(steps, axis=0)
    pts = poly[rng.integers(0, n, 300)] + rng.normal(0, spread, (300, 2))
    fp = PathDistance(poly).measure(pts)
    assert np.allclose(fp.distance_mm, brute_force_distance_mm(poly, pts), atol=1e-9, rtol=0)


def test_point_past_the_end_of_a_line_is_measured_to_the_end_point() -> None:
    fp = path_distance(np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[10.051, 0.0],
                                                                        [10.03, 0.04]]))
    assert fp.distance_mm == pytest.approx([0.051, 0.05])
    assert fp.t == pytest.approx([1.0, 1.0])
    assert fp.s_mm == pytest.approx([10.0, 10.0])


def test_overshoot_at_a_square_corner_is_the_overshoot() -> None:
    """G61 square: 51 um past the corner, on the line of the first side, is 51 um from the path
    (the next wall), though eq. 28 reads zero there; inside the corner the nearer side counts."""
    square = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0], [0.0, 0.0]])
    fp = path_distance(square, np.array([[20.051, 0.0], [19.99, 0.003], [20.02, 5.0]]))
    assert fp.distance_mm == pytest.approx([0.051, 0.003, 0.02])


def test_points_on_the_path_are_at_zero() -> None:
    poly = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, -1.0], [-2.0, 0.5]])
    t = np.linspace(0, 1, 7)[:, None]
    pts = np.vstack([poly, poly[0] + t * (poly[1] - poly[0]), poly[2] + t * (poly[3] - poly[2])])
    assert np.abs(path_distance(poly, pts).distance_mm).max() < 1e-12


def test_single_point_path() -> None:
    fp = path_distance(np.array([[1.0, 1.0]]), np.array([[4.0, 5.0]]))
    assert fp.distance_mm == pytest.approx([5.0])


@pytest.mark.parametrize("program", ["naca2415.nc", "butterfly.nc"])
def test_nurbs_polyline_chord_error_under_50_nm(program: str) -> None:
    blocks = list(read_program(str(REPO / "nc_programs" / program), load_config()))
    poly = path_polyline(blocks)
    curve = Nurbs.from_block(next(b for b in blocks if isinstance(b, NurbsBlock)))
    u = np.random.default_rng(3).uniform(curve.u_start, curve.u_end, 100_000)
    d = path_distance(poly, curve.evaluate(u, order=0)[0]).distance_mm
    assert d.max() < 5e-5
    # The polyline runs from the NURBS start to where the program stops (M2).
    assert np.allclose(poly[0], curve.evaluate(np.array([curve.u_start]), order=0)[0][0])
    stop = next(b for b in blocks if isinstance(b, StopBlock))
    assert np.allclose(poly[-1], stop.position[:2], atol=1e-12)


def test_arcs_and_lines_from_a_program(tmp_path: Path) -> None:
    prog = tmp_path / "arc.nc"
    prog.write_text("G17 G21 G90 F600\nG1 X10 Y0\nG3 X20 Y10 I0 J10\nG1 X20 Y20\nM2\n")
    poly = path_polyline(read_program(str(prog), load_config()))
    th = np.linspace(-np.pi / 2, 0, 1001)
    arc = np.column_stack([10 + 10 * np.cos(th), 10 + 10 * np.sin(th)])
    assert path_distance(poly, arc).distance_mm.max() < 5e-5
    # Centre of the arc: 10 mm from every point of it, and from the two lines' ends.
    assert path_distance(poly, np.array([[10.0, 10.0]])).distance_mm == pytest.approx([10.0],
                                                                                     abs=5e-5)
