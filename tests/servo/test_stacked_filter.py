"""All axes' servo filters run together in blocks equal each axis's own, run frame by frame."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from servo_helpers import FIFTH, TABLE_II

from controller.servo.model import discretise, filter_block, mismatched
from controller.servo.stacked import StackedFilter

TOL_MM = (2e-11, 2e-11, 1e-10)  # per kind: the 5th-order filter's states are larger


def servos(kinds: list[int]) -> list:
    table = (discretise(TABLE_II, 0.001), discretise(mismatched(TABLE_II, 20.0, 10.0), 0.001))
    return [FIFTH if k == 2 else table[k] for k in kinds]


def velocities(rng: np.random.Generator, n: int, axes: int) -> np.ndarray:
    """Per-frame velocities a table can follow: accelerations within Amax (2450 mm/s^2, the
    config's) each period, speeds within 250 mm/s."""
    accel_mm_s2 = rng.uniform(-2450.0, 2450.0, (n, axes))
    return np.clip(np.cumsum(accel_mm_s2 * 0.001, axis=0), -250.0, 250.0)


@settings(max_examples=40, deadline=None)
@given(
    kinds=st.lists(st.integers(0, 2), min_size=1, max_size=3),
    chunks=st.lists(st.integers(1, 600), min_size=1, max_size=5),
    seed=st.integers(0, 2**31 - 1),
)
def test_blocks_of_any_size_equal_the_per_frame_filter_of_each_axis(
    kinds: list[int], chunks: list[int], seed: int
) -> None:
    filters = servos(kinds)
    v = velocities(np.random.default_rng(seed), sum(chunks), len(kinds))
    stacked = StackedFilter(filters)
    got = np.vstack([stacked.step(part) for part in np.split(v, np.cumsum(chunks)[:-1])])
    parts = np.cumsum(chunks)[:-1]
    for axis, servo in enumerate(filters):
        state, blocks = np.zeros(servo.order), []
        for part in np.split(v[:, axis], parts):  # each axis alone, in the same blocks
            e, state = filter_block(servo, part, state)
            blocks.append(e)
        # The companion form's states are large next to its output: either order of the
        # sums rounds to ~1e-11 mm (the per-axis blocks and the per-frame path differ as much).
        assert np.max(np.abs(got[:, axis] - np.concatenate(blocks))) <= TOL_MM[kinds[axis]]
        assert np.allclose(stacked.axis_state(axis), state, rtol=1e-9, atol=1e-12)
        state, frames = np.zeros(servo.order), []
        for k in range(len(v)):  # the per-frame path: one sample at a time
            e, state = filter_block(servo, v[k : k + 1, axis], state)
            frames.append(e[0])
        assert np.max(np.abs(got[:, axis] - frames)) <= TOL_MM[kinds[axis]]


def test_an_empty_block_changes_nothing() -> None:
    stacked = StackedFilter(servos([0, 1]))
    stacked.step(np.ones((5, 2)))
    before = stacked.state.copy()
    assert stacked.step(np.zeros((0, 2))).shape == (0, 2)
    assert np.array_equal(stacked.state, before)
