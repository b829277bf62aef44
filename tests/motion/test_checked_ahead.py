"""Real time: the card's blocks stepped ahead are checked once, with the results and the fault
cycle of the checks run cycle by cycle (a following error, an implausible reading)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from refgen import circle_chunks
from runtime_helpers import xy_config

from controller.config import MachineConfig, load_config
from controller.motion import checked_ahead
from controller.motion.blocks import CheckedAhead
from controller.motion.checks import FerrorCheck, RefHistory
from controller.motion.feedback_check import FeedbackCheck
from controller.motion.loop import MotionController
from controller.motion.pacing import WallPacer
from controller.motion.source import ChunkSource
from controller.motion.types import MotionSettings, Outcome
from drivers.base import Feedback
from drivers.sim.card import SimCard

BLOCK = 32


class _Card:
    """Rows a card would hand out, and the block of BLOCK rows holding the next one unread."""

    def __init__(self, rows: Feedback) -> None:
        self.rows, self.read, self.ahead_takebacks = rows, 0, 0

    def rows_ahead(self) -> tuple[int, Feedback] | None:
        lo = self.read // BLOCK * BLOCK
        if lo >= len(self.rows):
            return None
        return self.ahead_takebacks, _cut(self.rows, lo, lo + BLOCK)

    def take(self, n: int) -> Feedback:
        self.read += n
        return _cut(self.rows, self.read - n, self.read)


def _cut(fb: Feedback, lo: int, hi: int) -> Feedback:
    return Feedback(fb.seq[lo:hi], fb.commanded_counts[lo:hi], fb.encoder_counts[lo:hi])


class _Checks:
    def __init__(self, config: MachineConfig) -> None:
        start = np.zeros(2, dtype=np.int64)
        self.ferr, self.fbcheck = FerrorCheck(config, start), FeedbackCheck(config, start)


def _stream(config: MachineConfig, n: int, jump_at: int | None, lag_at: int | None) -> tuple:
    """A history of n reference frames along X and their rows fed back (a steady lag; an
    encoder jump or a growing lag from a frame on)."""
    hist = RefHistory(4096, 2, config.sample_period_s)
    pulse = np.array([a.pulse_mm for a in config.axes])
    pos = np.zeros((n, 2))
    pos[:, 0] = np.cumsum(np.linspace(0.0, 0.05, n))
    counts = np.rint(pos / pulse).astype(np.int64)
    hist.append(pos, np.full(n, 50.0), np.arange(n), np.zeros(2), counts)
    enc = counts - np.array([3, 0])
    if jump_at is not None:
        enc[jump_at:, 0] += 100_000
    if lag_at is not None:
        enc[lag_at:, 0] -= np.arange(n - lag_at) * 40
    return hist, Feedback(np.arange(n, dtype=np.int64), counts, enc)


def _cycles(n: int) -> list[int]:
    """Rows a cycle reads: mostly 2, a late cycle's 3 now and then (crossing a block's end)."""
    sizes, done = [], 0
    while done < n:
        sizes.append(min(n - done, 3 if len(sizes) % 13 == 12 else 2))
        done += sizes[-1]
    return sizes


def _run(config: MachineConfig, stream: tuple, ahead: bool, take_back_at: int | None) -> tuple:
    hist, rows = stream
    checks, card = _Checks(config), _Card(rows)
    checked = CheckedAhead(checks, hist, lambda fb: fb, card if ahead else None)
    first: tuple | None = None
    for k, size in enumerate(_cycles(len(rows))):
        if k == take_back_at:
            card.ahead_takebacks += 1  # the block went back to the FIFO: what was checked is void
        fb, bad, done = checked.believed(card.take(size), settling=False)
        trip = None if done else checks.ferr.check(fb, hist)
        if first is None and (bad is not None or trip is not None):
            first = (k, bad or trip)
        checked.plan.plan_next()
    checked.plan.catch_up()
    state = (
        checks.ferr.max_abs_mm,
        checks.ferr.last_mm.tolist(),
        checks.fbcheck.last.tolist(),
        checks.fbcheck.last_seq,
        checks.fbcheck.corrupt,
    )
    return first, state, checked.plan.cycles_taken


@pytest.mark.parametrize(
    ("jump_at", "lag_at", "take_back_at"),
    [(None, None, None), (None, None, 40), (150, None, None), (None, 121, None), (None, 90, 30)],
)
def test_checked_ahead_gives_the_cycle_by_cycle_results(
    jump_at: int | None, lag_at: int | None, take_back_at: int | None
) -> None:
    config = xy_config()
    stream = _stream(config, 400, jump_at, lag_at)
    plain = _run(config, stream, ahead=False, take_back_at=take_back_at)
    ahead = _run(config, stream, ahead=True, take_back_at=take_back_at)
    assert ahead[:2] == plain[:2]  # the same fault at the same cycle, the same figures after
    assert plain[2] == 0 and ahead[2] > 0
    if jump_at is None and lag_at is None:
        assert plain[0] is None and ahead[2] > len(_cycles(400)) // 2  # most checked ahead
    else:
        assert plain[0] is not None


def _off_travel(config: MachineConfig) -> MachineConfig:
    """X's travel ends at 15 mm (and its 1 mm of slack) on the way round the 20 mm circle."""
    axes = (replace(config.axes[0], travel_mm=(-150.0, 15.0)), *config.axes[1:])
    return replace(config, axes=axes)


def _real_time_run(config: MachineConfig) -> tuple[Any, int]:
    card = SimCard(config, realtime=True)
    card.open()
    try:
        settings = MotionSettings.from_config(config)
        pacer = WallPacer(settings.cycle_frames * config.sample_period_s)
        ctrl = MotionController(config, card, ChunkSource(list(circle_chunks())), pacer, settings)
        result = ctrl.run()
    finally:
        card.close()
    return result, ctrl.ahead.plan.cycles_taken


def test_a_reading_off_the_travel_in_real_time_is_the_one_checked_cycle_by_cycle(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The real-time sim card's blocks stepped ahead, checked once: the fault names the same
    axis, reading and travel as the loop checking every cycle's rows (the frames and the
    axes' response are the same whenever the card clocks them), and the figures are the same
    up to it."""
    config = _off_travel(load_config("xy_table_paper"))
    ahead, taken = _real_time_run(config)
    monkeypatch.setattr(checked_ahead.AheadPlan, "plan_next", lambda self: None)
    plain, none_taken = _real_time_run(config)
    assert plain.outcome is Outcome.FAULT and "off its travel" in plain.message
    assert ahead.message == plain.message and not ahead.position_known
    assert taken > 50 and none_taken == 0
