"""An e-stop's take-back reads the card's level just before it, and one refused because the
card clocked on meanwhile is tried again: the stop still starts ESTOP_KEEP_MS out, not behind
the whole card FIFO."""

from __future__ import annotations

from typing import Any

import numpy as np
from refgen import circle_chunks
from test_motion import CFG, run

from controller.motion.loop import ESTOP_KEEP_MS, MotionController
from controller.motion.recall import TAKE_BACK_TRIES
from controller.motion.types import Outcome

V_MM_S = 58.333  # the circle's feed (refgen.circle_chunks)
AMAX = CFG.interpolator.max_accel_mm_s2
T = CFG.sample_period_s
KEPT = int(np.ceil(ESTOP_KEEP_MS * 1e-3 / T - 1e-9))
# the cycle's own frames, those kept, the stop at Amax, a few for the stop's rounding
BOUND_FRAMES = 2 + KEPT + int(np.ceil(V_MM_S / AMAX / T)) + 3


def _estop(recall: Any) -> tuple[int, Any, list[int], Any]:
    """The circle on the virtual sim card, an e-stop at 0.4 s; recall(card, real, n, keep)
    stands in for the card's recall_frames. Frames executed after the request, the result,
    the calls (n asked), the controller."""
    at: list[int] = []
    asked: list[int] = []
    ctrls: list[MotionController] = []

    def inject(card: Any, ctrl: MotionController, _: object) -> None:
        real = card.recall_frames

        def wrapped(n: int, keep: int) -> int:
            asked.append(n)
            return recall(card, real, n, keep)

        card.recall_frames = wrapped
        at.append(ctrl.figures.executed)
        ctrls.append(ctrl)
        ctrl.request_estop("e-stop by operator")

    result, _, rec, _ = run(list(circle_chunks()), inject=inject, at_s=0.4)
    return len(rec.commanded()) - at[0], result, asked, ctrls[0]


def test_a_take_back_refused_as_the_card_clocked_on_is_tried_again() -> None:
    clocked: list[int] = []

    def clocks_on_first(card: Any, real: Any, n: int, keep: int) -> int:
        if not clocked:  # the card clocks a frame between the level's read and the recall
            clocked.append(1)
            card.advance(1)
        return int(real(n, keep))

    frames, result, asked, ctrl = _estop(clocks_on_first)
    assert result.outcome is Outcome.ABORTED
    assert len(asked) == 2 and asked[1] <= asked[0]  # refused, then asked from the level then
    assert ctrl.stream.recalled_frames == asked[1] > 0
    assert frames <= BOUND_FRAMES


def test_a_drive_that_cannot_take_back_is_asked_once() -> None:
    frames, result, asked, ctrl = _estop(lambda card, real, n, keep: 0)
    assert result.outcome is Outcome.ABORTED
    assert len(asked) == 1 < TAKE_BACK_TRIES
    assert ctrl.stream.recalled_frames == 0
    assert frames > BOUND_FRAMES  # the stop came behind the whole FIFO
