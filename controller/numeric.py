"""Helpers the planner and the motion loop call thousands of times: cheaper forms of np.clip,
np.unique and functools.cached_property, and point-to-polyline distances."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


def clamp(x: np.ndarray | float, lo: np.ndarray | float, hi: np.ndarray | float) -> np.ndarray:
    """np.minimum(np.maximum(x, lo), hi), which is how np.clip is defined; numpy 2's np.clip
    goes through Python wrappers costing ~1 us a call, and the planner calls it thousands of
    times per program on arrays of a few dozen elements."""
    return np.minimum(np.maximum(x, lo), hi)


def sorted_unique(values: ArrayLike) -> np.ndarray:
    """The sorted distinct values (no NaN expected). numpy 2's plain np.unique asks
    np.ma.is_masked, which imports numpy.ma the first time: 20-25 ms that the generator would
    pay before the first motion of every `cncctl run`."""
    a = np.asarray(values).ravel()
    if a.size == 0:
        return a
    # Integers already in order (a sampled run's piece indices, by far the longest input) skip
    # the sort: O(n) to see, the same result. Floats are sorted always: -0.0 and 0.0 are equal
    # to the sort, which may put either first.
    if a.dtype.kind not in "iu" or not bool(np.all(a[1:] >= a[:-1])):
        a = np.sort(a)
    return a[np.concatenate(([True], a[1:] != a[:-1]))]


def is_in_sorted(values: ArrayLike, sorted_set: ArrayLike) -> np.ndarray:
    """np.isin(values, sorted_set) for a sorted set, by binary search (np.isin sorts, and its
    plain unique imports numpy.ma the first time, as above)."""
    v = np.asarray(values)
    s = np.asarray(sorted_set)
    if s.size == 0:
        return np.zeros(v.shape, bool)
    i = np.clip(np.searchsorted(s, v), 0, s.size - 1)
    return s[i] == v


def segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point from the segment [a, b] beside it (arrays broadcast: points
    (..., D) against segments (..., D)), the segment's ends included."""
    ab, ap = b - a, points - a
    len2 = _dot_last(ab, ab)
    t = _dot_last(ap, ab) / np.where(len2 > 0.0, len2, 1.0)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    gap = ap - t[..., None] * ab
    return np.sqrt(_dot_last(gap, gap))


def _dot_last(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """np.sum(x * y, axis=-1) to the bit (a short axis is summed in order), column by column:
    numpy reduces a last axis of 2 or 3 a few elements at a time, 2-5 times slower on the
    true contour error's thousands of points."""
    acc = x[..., 0] * y[..., 0]
    for i in range(1, x.shape[-1]):
        acc = acc + x[..., i] * y[..., i]
    return acc


def polyline_distance(
    points: np.ndarray, poly: np.ndarray, seg_len: np.ndarray | None = None
) -> np.ndarray:
    """Per row r, min over j of segment_distance(points[r], poly[:, r, j], poly[:, r, j + 1]):
    the distance of each point (R, D) from its own polyline, given axis first (D, R, W) so that
    every operation runs along rows of W (a last axis of 3 made numpy loop 3 at a time).

    The vertices' distances d_j come first; no point of segment j is nearer than
    (d_j + d_j+1 - len_j) / 2 (the triangle inequality from both its ends) and the nearest
    vertex is an answer, so only the segments whose bound is below it are measured with
    segment_distance: the same least distance at a fraction of the cost. seg_len (R, W - 1),
    the segments' lengths, when the caller has them cheaper (windows that overlap)."""
    # Sums of squares started from the first axis's, not from 0 (a pass less, the same bits).
    d_v = np.sqrt(_sum_rows(np.square(poly[i] - points[:, i, None]) for i in range(len(poly))))
    if seg_len is None:
        seg_len = np.sqrt(_sum_rows(np.square(np.diff(axis, axis=1)) for axis in poly))
    best = d_v.min(axis=1)
    row, j = np.nonzero(d_v[:, :-1] + d_v[:, 1:] - seg_len < 2.0 * best[:, None])
    if row.size:
        exact = segment_distance(points[row], poly[:, row, j].T, poly[:, row, j + 1].T)
        np.minimum.at(best, row, exact)
    return best


def _sum_rows(rows: Iterator[np.ndarray]) -> np.ndarray:
    total = next(rows)
    for row in rows:
        total = total + row
    return total


class cached_property:  # noqa: N801 (named as the functools one it replaces)
    """functools.cached_property without the lock Python 3.11 takes on every first access (3.12
    dropped it): 1.5 us less per PH blend's length and per curve's tables, of which a G1
    program has one per joint. The value is kept in the instance's __dict__, as there."""

    def __init__(self, func: Callable[[Any], Any]) -> None:
        self.func = func
        self.attrname = func.__name__
        self.__doc__ = func.__doc__

    def __set_name__(self, owner: type, name: str) -> None:
        self.attrname = name

    def __get__(self, instance: Any, owner: type | None = None) -> Any:  # noqa: ANN401
        if instance is None:
            return self
        value = self.func(instance)
        instance.__dict__[self.attrname] = value
        return value
