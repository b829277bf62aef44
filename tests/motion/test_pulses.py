"""Pulse accounting: the pulses sent always sum to the rounded latest commanded position."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.motion.pulses import PulseCounter, counts_of

PULSE = np.array([0.001, 0.0025])

positions = st.lists(st.tuples(st.floats(-200, 200), st.floats(-200, 200)), min_size=1,
                     max_size=60)
cuts = st.lists(st.integers(0, 60), max_size=6)


@settings(max_examples=200, deadline=None)
@given(positions, cuts, st.tuples(st.floats(-100, 100), st.floats(-100, 100)))
def test_pulses_sum_exactly_for_any_chunking(pts: list, cut_at: list, start: tuple) -> None:
    pos = np.array(pts)
    start_counts = counts_of(np.array(start), PULSE)
    counter = PulseCounter(PULSE, start_counts)
    sent = np.zeros(2, dtype=np.int64)
    bounds = sorted({0, len(pos), *[min(c, len(pos)) for c in cut_at]})
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        frames = counter.frames(pos[a:b])
        assert frames.dtype == np.int64 and frames.shape == (b - a, 2)
        sent += frames.sum(axis=0)
        # After every chunk: accumulated pulses == round(latest position / pulse).
        assert np.array_equal(start_counts + sent, counts_of(pos[b - 1], PULSE))
    assert np.array_equal(counter.commanded_counts, sent)


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 3000), st.floats(0.01, 99.0))
def test_no_drift_over_a_long_constant_feed(n: int, v_mm_s: float) -> None:
    """1 ms samples at a feed that is not a multiple of the pulse: the remainder is carried."""
    counter = PulseCounter(PULSE[:1], np.zeros(1, dtype=np.int64))
    t = np.arange(1, n + 1) * 1e-3
    frames = np.concatenate([counter.frames(c[:, None]) for c in np.array_split(v_mm_s * t, 7)])
    assert frames.sum() == np.rint(v_mm_s * t[-1] / PULSE[0])
    # Each frame is the floor or ceil of the ideal increment, never more off.
    assert np.abs(frames - v_mm_s * 1e-3 / PULSE[0]).max() < 1.0 + 1e-9


def test_empty_chunk_keeps_state() -> None:
    counter = PulseCounter(PULSE, np.array([5, -3]))
    assert counter.frames(np.zeros((0, 2))).shape == (0, 2)
    assert np.array_equal(counter.frames(np.array([[0.0051, -0.0075]])), [[0, 0]])
