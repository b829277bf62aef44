"""The generator's stand-ins for np.unique and np.isin give numpy's answers; the pruned
point-to-polyline distance gives the brute-force one."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.numeric import is_in_sorted, polyline_distance, segment_distance, sorted_unique

values = st.lists(st.integers(-5, 5), max_size=30)


@settings(max_examples=100, deadline=None)
@given(values)
def test_sorted_unique_is_np_unique(v: list[int]) -> None:
    a = np.array(v, dtype=float)
    np.testing.assert_array_equal(sorted_unique(a), np.unique(a))


@settings(max_examples=100, deadline=None)
@given(values, st.booleans())
def test_sorted_unique_of_integers_is_np_unique(v: list[int], ordered: bool) -> None:
    a = np.array(sorted(v) if ordered else v, dtype=np.intp)
    got = sorted_unique(a)
    np.testing.assert_array_equal(got, np.unique(a))
    assert got.dtype == a.dtype


@settings(max_examples=100, deadline=None)
@given(values, values)
def test_is_in_sorted_is_np_isin(v: list[int], s: list[int]) -> None:
    a, members = np.array(v), np.sort(np.array(s, dtype=int))
    np.testing.assert_array_equal(is_in_sorted(a, members), np.isin(a, members))


def _plain_segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """segment_distance as it was written with np.sum over the last axis."""
    ab, ap = b - a, points - a
    len2 = np.sum(ab * ab, axis=-1)
    t = np.sum(ap * ab, axis=-1) / np.where(len2 > 0.0, len2, 1.0)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    gap = ap - t[..., None] * ab
    return np.sqrt(np.sum(gap * gap, axis=-1))


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 300), st.sampled_from([2, 3]), st.integers(0, 2**31 - 1),
       st.floats(1e-9, 1e3))
def test_segment_distance_is_the_plain_form_to_the_bit(n: int, dims: int, seed: int,
                                                        scale: float) -> None:
    rng = np.random.default_rng(seed)
    points, a, b = (scale * rng.normal(size=(n, dims)) for _ in range(3))
    b[::5] = a[::5]  # zero-length segments
    points[::7] = a[::7]  # points on an end
    np.testing.assert_array_equal(segment_distance(points, a, b),
                                  _plain_segment_distance(points, a, b))
    # broadcast as polyline_distance's brute form uses it: points (R, 1, D), segments (R, W, D)
    poly = scale * rng.normal(size=(n, 4, dims))
    np.testing.assert_array_equal(
        segment_distance(points[:, None, :], poly[:, :-1], poly[:, 1:]),
        _plain_segment_distance(points[:, None, :], poly[:, :-1], poly[:, 1:]))


def _brute(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Every segment measured, poly as rows of vertices (R, W, D)."""
    return segment_distance(points[:, None, :], poly[:, :-1], poly[:, 1:]).min(axis=1)


# Polylines with steps of very different sizes, repeated vertices (a stop) and turns back.
steps = st.lists(st.sampled_from([0.0, 1e-3, 0.01, 0.3, 2.0, -0.5]), min_size=6, max_size=6)


@settings(max_examples=200, deadline=None)
@given(
    st.integers(1, 5),
    st.integers(2, 12),
    st.sampled_from([2, 3]),
    st.integers(0, 2**31 - 1),
    steps,
    st.floats(1e-4, 5.0),
)
def test_polyline_distance_is_the_least_segment_distance(
    rows: int, width: int, dims: int, seed: int, step_mm: list[float], off_mm: float
) -> None:
    rng = np.random.default_rng(seed)
    size = rng.choice(step_mm, size=(rows, width - 1, 1)) * rng.uniform(
        0.5, 1.0, (rows, width - 1, 1)
    )
    heading = rng.normal(size=(rows, width - 1, dims))
    poly = np.concatenate(
        [
            rng.normal(size=(rows, 1, dims)),
            size * heading / np.linalg.norm(heading, axis=2, keepdims=True),
        ],
        axis=1,
    ).cumsum(axis=1)
    near = poly[np.arange(rows), rng.integers(0, width, rows)]
    points = near + off_mm * rng.normal(size=(rows, dims))
    got = polyline_distance(points, np.ascontiguousarray(poly.transpose(2, 0, 1)))
    np.testing.assert_allclose(got, _brute(points, poly), rtol=0.0, atol=1e-12)


def test_polyline_distance_with_given_lengths_measures_the_nearest_segment_exactly() -> None:
    """A point beside the middle of a long segment, far from both its ends: the vertices alone
    would say 5 mm, the segment is 0.1 mm away."""
    poly = np.array([[[-20.0, 0.0], [-10.0, 0.0], [10.0, 0.0], [20.0, 0.0]]])
    points = np.array([[0.0, 0.1]])
    lengths = np.array([[10.0, 20.0, 10.0]])
    axis_first = np.ascontiguousarray(poly.transpose(2, 0, 1))
    assert polyline_distance(points, axis_first, lengths)[0] == _brute(points, poly)[0]
    assert abs(polyline_distance(points, axis_first)[0] - 0.1) < 1e-12
