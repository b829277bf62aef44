"""Helpers the planner calls thousands of times: cheaper forms of np.clip, np.unique and
functools.cached_property."""

from __future__ import annotations

from collections.abc import Callable
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
    a = np.sort(np.asarray(values).ravel())
    if a.size == 0:
        return a
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
    (..., 2) against segments (..., 2)), the segment's ends included."""
    ab, ap = b - a, points - a
    len2 = np.sum(ab * ab, axis=-1)
    t = np.sum(ap * ab, axis=-1) / np.where(len2 > 0.0, len2, 1.0)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    gap = ap - t[..., None] * ab
    return np.sqrt(np.sum(gap * gap, axis=-1))


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
