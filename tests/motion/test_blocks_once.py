"""A virtual-time block's work done once: its rows checked by its cut only (the cycle that reads
them takes the checks as they stand after them), and its journal entries made only when a
take-back asks for them (the same entries as made at once)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from refgen import circle_chunks
from runtime_helpers import virtual_card

from controller.config import load_config
from controller.motion import checks, feedback_check
from controller.motion.blocks import BlockSend
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.recall import JOURNAL_ENTRIES, SendJournal, Sent
from controller.motion.source import ChunkSource
from controller.motion.types import Outcome


def _checked_rows(blocks: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[dict[str, int], Any]:
    """Rows given to each check over a run of the circle, and the run's result."""
    rows = {"ferr": 0, "fbcheck": 0}
    ferr_check, fb_check = checks.FerrorCheck.check, feedback_check.FeedbackCheck.check

    def ferr(self: Any, fb: Any, hist: Any = None) -> Any:
        rows["ferr"] += len(fb)
        return ferr_check(self, fb, hist)

    def fbc(self: Any, fb: Any, settling: bool = False) -> Any:
        rows["fbcheck"] += len(fb)
        return fb_check(self, fb, settling)

    config = load_config("xy_table_paper")
    card = virtual_card(config)
    until = card.advance_until if blocks else None
    pacer = VirtualPacer(2, config.sample_period_s, card.advance, advance_until=until)
    ctrl = MotionController(config, card, ChunkSource(list(circle_chunks())), pacer)
    with monkeypatch.context() as patch:
        patch.setattr(checks.FerrorCheck, "check", ferr)
        patch.setattr(feedback_check.FeedbackCheck, "check", fbc)
        return rows, ctrl.run()


def test_each_row_of_a_block_run_is_checked_once(monkeypatch: pytest.MonkeyPatch) -> None:
    cycles, result_c = _checked_rows(False, monkeypatch)
    blocks, result_b = _checked_rows(True, monkeypatch)
    assert result_b.outcome is result_c.outcome is Outcome.DONE
    assert blocks == cycles  # cut's check, not the cycle's again (twice as many rows before)
    assert result_b.following_error_um_max == result_c.following_error_um_max


def _block(start: int, frames: int) -> BlockSend:
    retimer = {"back": np.zeros((0, 4)), "recent": np.zeros((0, 2))}
    before = Sent(0, np.zeros((0, 4)), retimer, np.zeros(2), np.zeros(2), np.zeros(2), start)
    consumed = np.column_stack((np.arange(start, start + frames, dtype=float),) * 4)
    return BlockSend(before, consumed, np.zeros((frames, 2), np.int64), None)


@pytest.mark.parametrize("blocks", [3, 40])  # a few; more sends than the journal keeps
def test_a_journalled_block_gives_the_sends_made_at_once(blocks: int) -> None:
    lazy, eager = SendJournal(), SendJournal()
    start = 0
    for k in range(blocks):
        frames = 64 if k % 3 else 62  # a block may end in a shorter send
        lazy.record_block(_block(start, frames), 2)
        for entry in _block(start, frames).pieces(2):
            eager.record(entry.frames, entry.consumed, entry)
        eager.record(1, np.zeros((1, 4)), _block(start + frames, 1).before)
        lazy.record(1, np.zeros((1, 4)), _block(start + frames, 1).before)
        start += frames + 1
    for budget in (5, 66, 10_000):
        got, want = lazy.newest_within(budget), eager.newest_within(budget)
        assert [e.frames for e in got] == [e.frames for e in want]
        assert all(np.array_equal(g.consumed, w.consumed) for g, w in zip(got, want, strict=True))
        assert [e.hist_count for e in got] == [e.hist_count for e in want]
    assert len(lazy.newest_within(10**9)) == min(JOURNAL_ENTRIES, len(eager.entries))
    lazy.drop(3)
    eager.drop(3)
    assert [e.hist_count for e in lazy.newest_within(10**9)] == [
        e.hist_count for e in eager.newest_within(10**9)
    ]
