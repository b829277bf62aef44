"""The real-time sim card clocked in blocks: what a host reads is what a card clocked period by
period gives (the same rows, an underrun at the same frame, injections and take-backs at the
frame they came)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest
from runtime_helpers import virtual_card, xy_config

from drivers.base import CardStatus, Feedback
from drivers.errors import BadFrameError, UnderrunError
from drivers.registry import make_drive
from drivers.sim.card import SimCard


def ramp_frames(n: int, per_frame: int = 40) -> np.ndarray:
    return np.tile([per_frame, -per_frame], (n, 1)).astype(np.int64)


def realtime_card() -> SimCard:
    card = make_drive(xy_config(), realtime=True)
    assert isinstance(card, SimCard)
    card.open()
    return card


def joined(parts: list[Feedback]) -> Feedback:
    return Feedback(
        np.concatenate([p.seq for p in parts]),
        np.concatenate([p.commanded_counts for p in parts]),
        np.concatenate([p.encoder_counts for p in parts]),
    )


def head(fb: Feedback, rows: int) -> Feedback:
    return Feedback(fb.seq[:rows], fb.commanded_counts[:rows], fb.encoder_counts[:rows])


def read_all(card: SimCard, until: Callable[[], bool], timeout_s: float = 10.0) -> Feedback:
    """Feedback read every 2 ms (a host's cycle) until `until()`, then once more."""
    parts = []
    deadline_s = time.monotonic() + timeout_s
    while not until() and time.monotonic() < deadline_s:
        parts.append(card.feedback())
        time.sleep(0.002)
    parts.append(card.feedback())
    return joined(parts)


def replayed(
    frames: np.ndarray,
    at: int = -1,
    inject: Callable[[SimCard], None] | None = None,
    eos: bool = True,
) -> Feedback:
    """The same frames on a virtual card clocked period by period, `inject` after `at` frames."""
    card = virtual_card(xy_config())
    card.write_frames(frames, end_of_stream=eos)
    rows = []
    for k in range(len(frames)):
        if k == at and inject is not None:
            inject(card)
        card.advance(1)
        rows.append(card.feedback())
    return joined(rows)


def assert_same_rows(got: Feedback, want: Feedback) -> None:
    np.testing.assert_array_equal(got.seq, want.seq)
    np.testing.assert_array_equal(got.commanded_counts, want.commanded_counts)
    np.testing.assert_array_equal(got.encoder_counts, want.encoder_counts)


def test_rows_read_each_cycle_are_those_of_a_card_clocked_period_by_period() -> None:
    frames = ramp_frames(200)
    card = realtime_card()
    try:
        card.write_frames(frames, end_of_stream=True)
        levels = []
        fb = read_all(card, lambda: levels.append(card.fifo_level()) or levels[-1] == 0)
        status = card.status()
    finally:
        card.close()
    assert status == CardStatus.OK
    assert levels == sorted(levels, reverse=True) and levels[-1] == 0
    assert_same_rows(fb, replayed(frames))


def test_a_frame_written_after_its_period_is_an_underrun_at_that_frame() -> None:
    card = realtime_card()
    try:
        card.write_frames(ramp_frames(30))  # no end of stream: more was to come
        time.sleep(0.1)  # 30 ms of frames, then nothing for 70 ms
        with pytest.raises(UnderrunError, match="after frame 29"):
            card.write_frames(ramp_frames(10))
        fb = card.feedback()
        cmd, _ = card.position_counts()
    finally:
        card.close()
    np.testing.assert_array_equal(fb.seq, np.arange(30))
    np.testing.assert_array_equal(cmd, [30 * 40, -30 * 40])


@pytest.mark.parametrize(
    "inject",
    [
        lambda card: card.inject_stall(0),
        lambda card: card.inject_lag(1, 0.2, ramp_frames=5),
        lambda card: card.inject_drive_fault(0),
    ],
)
def test_an_injection_inside_a_block_acts_from_the_frame_it_came(
    inject: Callable[[SimCard], None],
) -> None:
    frames = ramp_frames(250)
    card = realtime_card()
    try:
        card.write_frames(frames, end_of_stream=True)
        time.sleep(0.05)
        before = card.feedback()
        inject(card)  # some periods later than the rows just read; none ahead of time
        after = read_all(card, lambda: card.fifo_level() == 0 or card.status().halted)
    finally:
        card.close()
    fb = joined([before, after])
    clocked = len(fb.seq)
    # The rows up to the injection: as clocked period by period; then the injection at the
    # frame the rows read show (searched over the few periods between the read and it).
    for at in range(len(before.seq), min(clocked, len(before.seq) + 40) + 1):
        want = replayed(frames, at, inject)
        rows = min(clocked, len(want.seq))
        if np.array_equal(fb.encoder_counts[:rows], want.encoder_counts[:rows]):
            assert_same_rows(head(fb, rows), head(want, rows))
            return
    pytest.fail("no frame of injection gives the rows read")


def test_frames_taken_back_inside_a_block_never_run() -> None:
    card = realtime_card()
    try:
        card.write_frames(ramp_frames(200))
        time.sleep(0.03)
        level = card.fifo_level()
        got = card.recall_frames(100, keep=10)
        card.write_frames(np.zeros((0, 2), dtype=np.int64), end_of_stream=True)
        fb = read_all(card, lambda: card.fifo_level() == 0)
        cmd, _ = card.position_counts()
        status = card.status()
    finally:
        card.close()
    assert level > 100 and got == 100 and status == CardStatus.OK
    np.testing.assert_array_equal(cmd, [100 * 40, -100 * 40])
    assert_same_rows(fb, replayed(ramp_frames(100)))


def test_a_halt_inside_a_block_clocks_no_frame_after_it() -> None:
    card = realtime_card()
    try:
        card.write_frames(ramp_frames(200))
        time.sleep(0.03)
        with pytest.raises(BadFrameError):
            card.write_frames(np.array([[500, 0]]))  # more pulses than a frame may hold
        fb = card.feedback()
        time.sleep(0.05)
        later = card.feedback()
        cmd, _ = card.position_counts()
        level = card.fifo_level()
    finally:
        card.close()
    assert len(later.seq) == 0 and level == 200 - len(fb.seq)
    np.testing.assert_array_equal(cmd, fb.commanded_counts[-1])


def test_a_card_opened_again_clocks_from_then_on() -> None:
    """Its periods go on from the reopening (they did not restart from 0 behind the periods
    already clocked: the card stood still as long as it had been open)."""
    card = realtime_card()
    try:
        card.write_frames(ramp_frames(100), end_of_stream=True)
        time.sleep(1.0)
        card.close()
        card.open()
        t0_s = time.monotonic()
        card.write_frames(ramp_frames(100), end_of_stream=True)
        fb = read_all(card, lambda: card.fifo_level() == 0, timeout_s=5.0)
        took_s = time.monotonic() - t0_s
    finally:
        card.close()
    np.testing.assert_array_equal(fb.seq, np.arange(200))
    assert took_s < 0.9  # 100 periods of 1 ms (not after the 1 s clocked before)
