"""np.unique for plain sorted unique values, without numpy importing numpy.ma on first use."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


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
