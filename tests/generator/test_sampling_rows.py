"""Sampling's grouping of sample rows by piece: one pass over the rows, the same groups as a
search per piece."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.generator.sampling import _rows_by_piece


@settings(max_examples=200, deadline=None)
@given(idx=st.lists(st.integers(0, 12), max_size=200),
       pieces=st.lists(st.integers(0, 12), min_size=1, max_size=8, unique=True))
def test_rows_by_piece_equal_a_search_per_piece(idx: list[int], pieces: list[int]) -> None:
    idx_a, pieces_a = np.array(sorted(idx), np.intp), np.array(pieces, np.intp)
    rows, count = _rows_by_piece(pieces_a, idx_a)
    each = [np.flatnonzero(idx_a == i) for i in pieces]
    assert rows.tolist() == np.concatenate(each).tolist()
    assert count.tolist() == [r.size for r in each]
