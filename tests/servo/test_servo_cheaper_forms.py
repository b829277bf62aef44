"""The servo side's cheaper forms give the bits of the forms they replace, on random input."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from servo_helpers import FIFTH, TABLE_II, draw_polyline

from controller.config import load_config
from controller.numeric import segment_distance
from controller.runtime.simulate_stream import ServoStream
from controller.runtime.simulation import tangent_angles
from controller.servo.model import (
    BLOCK,
    DiscreteServo,
    contour_error_mm,
    discretise,
    filter_block,
    filter_state,
)
from controller.servo.true_distance import (
    distance_from_reference_mm,
    own_bound_mm,
    segment_columns,
    window_distance_mm,
)
from controller.servo.window_search import GROUP_SEGMENTS, _group_boxes


def bits(a: np.ndarray) -> list[int]:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64).ravel().tolist()


def old_filter_block(
    servo: DiscreteServo, u: np.ndarray, state: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """filter_block as it was: views of the block matrices cut to every block, the outputs
    as the free response plus the Toeplitz product."""
    obs, toeplitz, reach, powers = servo._blocks
    out = np.empty(len(u))
    x = state.copy()
    for k0 in range(0, len(u), BLOCK):
        chunk = u[k0 : k0 + BLOCK]
        m = len(chunk)
        out[k0 : k0 + m] = obs[:m] @ x + toeplitz[:m, :m] @ chunk
        x = powers[m] @ x + reach[:, BLOCK - m :] @ chunk
    return out, x


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.integers(0, 3 * BLOCK + 7),
    st.sampled_from([0, 1, 2]),
    st.booleans(),
)
def test_filter_block_and_filter_state_are_the_old_form_bit_for_bit(
    seed: int, n: int, kind: int, strided: bool
) -> None:
    """Any length (whole blocks, a part block, none), a strided column or a contiguous one."""
    servo = (discretise(TABLE_II, 0.001), discretise(TABLE_II, 0.0005), FIFTH)[kind]
    rng = np.random.default_rng(seed)
    rows = rng.standard_normal((n, 3)) * rng.choice([1e-3, 1.0, 300.0])
    u = rows[:, 1] if strided else np.ascontiguousarray(rows[:, 1])
    state = rng.standard_normal(servo.order) * 1e-3
    out, x = filter_block(servo, u, state)
    old_out, old_x = old_filter_block(servo, u, state)
    assert bits(out) == bits(old_out) and bits(x) == bits(old_x)
    assert bits(filter_state(servo, u, state)) == bits(old_x)


@st.composite
def _polyline_and_points(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    """A polyline (random walk, folding curve, repeated points: zero-length segments) and a
    point near each of its vertices (some exactly on them)."""
    rng, ref = draw_polyline(draw, 700, 500.0)
    n = len(ref)
    act = np.roll(ref, draw(st.integers(0, 30)), axis=0)
    off = rng.standard_normal(ref.shape) * draw(st.floats(0.0, 0.01))
    act = act + np.where(rng.random((n, 1)) < 0.2, 0.0, off)
    return ref, act


def old_bound(ref: np.ndarray, act: np.ndarray) -> np.ndarray:
    """The own-segment bound as it was: segment_distance to the segments before and at."""
    n = len(ref)
    own = np.arange(n)
    before, at = np.clip(own - 1, 0, n - 2), np.clip(own, 0, n - 2)
    return np.minimum(
        segment_distance(act, ref[before], ref[before + 1]),
        segment_distance(act, ref[at], ref[at + 1]),
    )


@settings(max_examples=60, deadline=None)
@given(_polyline_and_points())
def test_the_own_segment_bound_from_segment_terms_is_segment_distance(case: tuple) -> None:
    ref, act = case
    n = len(ref)
    own = np.arange(n)
    before, at = np.clip(own - 1, 0, n - 2), np.clip(own, 0, n - 2)
    cols = segment_columns(ref)
    assert bits(own_bound_mm(cols, act, before, at)) == bits(old_bound(ref, act))
    if n > 2:  # slices, as the stream reads them where nothing is clipped
        inner = own_bound_mm(cols, act[1:-1], slice(0, n - 2), slice(1, n - 1))
        assert bits(inner) == bits(old_bound(ref, act)[1:-1])


@settings(max_examples=40, deadline=None)
@given(_polyline_and_points(), st.sampled_from([0.0, 1e-6, 1e-3]), st.integers(1, 50))
def test_distance_from_reference_is_the_old_form_bit_for_bit(
    case: tuple, exact_above_mm: float, near: int
) -> None:
    """The generator's and simulate's true distance: the bound, then the pruned windows where
    it is above exact_above_mm, against the old bound and the full window search."""
    ref, act = case
    bound = old_bound(ref, act)
    k = np.flatnonzero(bound > exact_above_mm)
    want = bound.copy()
    want[k] = window_distance_mm(ref, act[k], k, near)
    assert bits(distance_from_reference_mm(ref, act, exact_above_mm, near)) == bits(want)


def old_group_boxes(columns: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """_group_boxes as it was: the least and greatest along rows of GROUP_SEGMENTS."""
    ax, ay, abx, aby, _ = columns
    n_groups = -(-len(ax) // GROUP_SEGMENTS)
    out = []
    for start, step in ((ax, abx), (ay, aby)):
        end = start + step
        for reduce, fill, pick in ((np.min, np.inf, np.minimum), (np.max, -np.inf, np.maximum)):
            padded = np.full(n_groups * GROUP_SEGMENTS, fill)
            padded[: len(start)] = pick(start, end)
            out.append(reduce(padded.reshape(n_groups, GROUP_SEGMENTS), axis=1))
    return tuple(out)


@settings(max_examples=40, deadline=None)
@given(_polyline_and_points())
def test_group_boxes_are_the_old_reduction(case: tuple) -> None:
    ref, _ = case
    cols = list(segment_columns(ref))
    new, old = _group_boxes(cols), old_group_boxes(cols)
    assert [bits(b) for b in new] == [bits(b) for b in old]


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.lists(st.integers(1, 400), min_size=1, max_size=8))
def test_the_streams_tangents_are_the_whole_arrays(seed: int, sizes: list[int]) -> None:
    """Chunks with and without the generator's exact tangent, the path stopping now and then
    (repeated points): the stream's contour error is eq. 28 on tangent_angles of the whole
    reference with the exact tangents over it, the settling holding the last one."""
    config = load_config(None)
    rng = np.random.default_rng(seed)
    n = sum(sizes)
    steps = rng.standard_normal((n, 2)) * 0.01 * (rng.random((n, 1)) < 0.8)
    ref = np.cumsum(steps, axis=0)
    exact = [rng.random() < 0.5 for _ in sizes]
    phis = [rng.uniform(-np.pi, np.pi, m) for m in sizes]
    stream, blocks, k = ServoStream(config), [], 0
    for m, has, phi in zip(sizes, exact, phis, strict=True):
        chunk = slice(k, k + m)
        blocks += stream.push(
            ref[chunk], np.zeros(m), np.zeros(m, int), False, phi if has else None
        )
        k += m
    blocks += stream.finish()
    contour = np.concatenate([b.contour_mm for b in blocks])
    ex, ey = (np.concatenate([getattr(b, f) for b in blocks]) for f in ("ex_mm", "ey_mm"))
    held = np.vstack([ref, np.repeat(ref[-1:], len(ex) - n, axis=0)])
    phi = tangent_angles(held)
    k = 0
    for m, has, p in zip(sizes, exact, phis, strict=True):
        if has:
            phi[k : k + m] = p
        k += m
    phi[n:] = phi[n - 1]
    assert bits(contour) == bits(contour_error_mm(ex, ey, phi))


@settings(max_examples=40, deadline=None)
@given(_polyline_and_points(), st.integers(0, 2**32 - 1), st.integers(1, 50))
def test_repeated_samples_as_a_band_gives_them_are_searched_each_on_its_own(
    case: tuple, seed: int, near: int
) -> None:
    """Sorted samples with repeats and gaps (a servo band's plants share samples; [5, 5, 7] has
    the ends of three consecutive ones): both searches give each point's own window's least."""
    ref, act = case
    rng = np.random.default_rng(seed)
    n = len(ref)
    k = np.sort(rng.integers(0, n, rng.integers(1, 2 * n + 1)))
    if len(k) >= 3:
        k[:3] = [k[0], k[0], min(k[0] + 2, n - 1)]
        k.sort()
    points = act[k] + rng.standard_normal((len(k), 2)) * 1e-6
    one_by_one = np.array(
        [window_distance_mm(ref, points[i : i + 1], k[i : i + 1], near)[0] for i in range(len(k))]
    )
    bound = np.full(len(k), np.inf)  # no pruning by distance: every box meets the square
    assert bits(window_distance_mm(ref, points, k, near)) == bits(one_by_one)
    assert bits(window_distance_mm(ref, points, k, near, bound)) == bits(one_by_one)
