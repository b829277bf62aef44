"""A hold planned before the card's frames are taken back: a loop descheduled while it plans
never runs the card dry (the virtual sim card clocks on while the ramp is planned)."""

from __future__ import annotations

import math

from refgen import circle_chunks

from controller.config import load_config
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.ramp_first import HOLD_KEEP_MS, PLAN_BUDGET_MS, PLAN_TRIES
from controller.motion.source import ChunkSource
from controller.motion.types import MotionProgress, MotionSettings, MotionState, Outcome
from drivers.errors import LostCommunicationError
from drivers.sim.card import SimCard

CFG = load_config("xy_table")
T = CFG.sample_period_s
# More than the first try keeps queued beyond the take-back while it plans: a ramp planned
# after the take-back (keeping only HOLD_KEEP_MS) would leave the card dry this long.
STALL_FRAMES = 2 * (math.ceil(HOLD_KEEP_MS * 1e-3 / T) + math.ceil(PLAN_BUDGET_MS * 1e-3 / T))


def _hold_with_stalls(
    stalls: list[int], refuse: bool = False
) -> tuple[object, MotionController, dict]:
    """The circle on the virtual sim card, a hold at 0.4 s, resumed once held; the card clocks
    stalls[i] frames during the i-th ramp planning after the request (the loop descheduled
    there). refuse: the card takes nothing back and its level cannot be read just after (a
    link lost then; the cycle's next read finds it again)."""
    card = SimCard(CFG, realtime=False)
    card.open()
    if refuse:
        level = card.fifo_level

        def refused(n: int, keep: int) -> int:
            info["refused"] = info.get("refused", 0) + 1
            card.fifo_level = lost  # type: ignore[method-assign]
            return 0

        def lost() -> int:
            card.fifo_level = level  # type: ignore[method-assign]
            raise LostCommunicationError("no reply")

        card.recall_frames = refused  # type: ignore[method-assign]
    settings = MotionSettings.from_config(CFG, progress_every_s=T)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    info: dict = {"plans": 0}

    def progress(p: MotionProgress) -> None:
        if "asked" not in info and p.executed_s >= 0.4:
            info["asked"] = True
            ctrl.request_hold()
        if p.state is MotionState.HELD and "held" not in info:
            info["held"] = True
            ctrl.request_resume()

    ctrl = MotionController(
        CFG, card, ChunkSource(list(circle_chunks())), pacer, settings, on_progress=progress
    )
    plan = ctrl.retimer.plan

    def descheduled(held):  # noqa: ANN001, ANN202
        if "asked" in info and stalls:
            info["plans"] += 1
            card.advance(stalls.pop(0))  # the card runs on while the loop plans
        plan(held)

    ctrl.retimer.plan = descheduled  # type: ignore[method-assign]
    result = ctrl.run()
    card.close()
    return result, ctrl, info


def test_a_plan_that_overruns_its_budget_is_planned_again_from_further_on() -> None:
    result, ctrl, info = _hold_with_stalls([STALL_FRAMES])
    assert result.outcome is Outcome.DONE and result.underruns == 0  # type: ignore[attr-defined]
    assert info["held"] and info["plans"] == 1
    assert ctrl.stream.recalled_frames > 0  # the second try took frames back


def test_every_try_overrun_the_ramp_starts_behind_the_queue() -> None:
    result, ctrl, info = _hold_with_stalls([STALL_FRAMES] * (PLAN_TRIES + 1))
    assert result.outcome is Outcome.DONE and result.underruns == 0  # type: ignore[attr-defined]
    assert info["held"] and info["plans"] == PLAN_TRIES + 1  # the last: planned behind it all
    assert ctrl.stream.recalled_frames == 0


def test_a_plan_within_its_budget_takes_back_at_the_first_try() -> None:
    budget = math.ceil(PLAN_BUDGET_MS * 1e-3 / T)
    result, ctrl, info = _hold_with_stalls([budget])
    assert result.outcome is Outcome.DONE and result.underruns == 0  # type: ignore[attr-defined]
    assert info["held"] and info["plans"] == 1 and ctrl.stream.recalled_frames > 0


def test_a_level_unreadable_after_a_refused_take_back_leaves_the_ramp_behind_the_queue() -> None:
    result, ctrl, info = _hold_with_stalls([], refuse=True)
    assert result.outcome is Outcome.DONE and result.underruns == 0  # type: ignore[attr-defined]
    assert info["held"] and info["refused"] == 1 and ctrl.stream.recalled_frames == 0
