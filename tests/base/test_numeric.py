"""The generator's stand-ins for np.unique and np.isin give numpy's answers."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.numeric import is_in_sorted, sorted_unique

values = st.lists(st.integers(-5, 5), max_size=30)


@settings(max_examples=100, deadline=None)
@given(values)
def test_sorted_unique_is_np_unique(v: list[int]) -> None:
    a = np.array(v, dtype=float)
    np.testing.assert_array_equal(sorted_unique(a), np.unique(a))


@settings(max_examples=100, deadline=None)
@given(values, values)
def test_is_in_sorted_is_np_isin(v: list[int], s: list[int]) -> None:
    a, members = np.array(v), np.sort(np.array(s, dtype=int))
    np.testing.assert_array_equal(is_in_sorted(a, members), np.isin(a, members))
