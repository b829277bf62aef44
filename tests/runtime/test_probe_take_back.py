"""A probe's trip takes the card's frames back as the e-stop does, through the controller's
own take_back_beyond_ms (the e-stop's): from the level read just before
(SendState.take_back_now, tests/motion/test_take_back_now.py), keeping PROBE_KEEP_MS."""

from __future__ import annotations

import math
from types import MethodType, SimpleNamespace
from typing import Any

import pytest

from controller.motion.loop import ESTOP_KEEP_MS, MotionController
from controller.motion.types import MotionState
from controller.runtime.probe_run import PROBE_KEEP_MS, _take_back


def _ctrl(log: list[tuple[Any, int]], **state: Any) -> Any:
    """The controller's state the take-back reads, with MotionController's own methods."""
    stream = SimpleNamespace(take_back_now=lambda drive, keep: log.append((drive, keep)))
    base = {"state": MotionState.RUNNING, "sent_eos": False, "pausing": False, "pending_tail": None}
    ctrl = SimpleNamespace(**{**base, **state}, stream=stream, drive="card", period_s=0.001)
    ctrl.frames_for_ms = MethodType(MotionController.frames_for_ms, ctrl)
    ctrl.take_back_beyond_ms = MethodType(MotionController.take_back_beyond_ms, ctrl)
    return ctrl


def test_a_trip_keeps_what_the_estop_keeps_in_the_card() -> None:
    log: list[tuple[Any, int]] = []
    _take_back(_ctrl(log))
    assert PROBE_KEEP_MS >= ESTOP_KEEP_MS
    assert log == [("card", math.ceil(PROBE_KEEP_MS - 1e-9))]


@pytest.mark.parametrize(
    "state",
    [
        {"sent_eos": True},
        {"pausing": True},
        {"pending_tail": object()},
        {"state": MotionState.STOPPING},
    ],
)
def test_nothing_is_taken_back_when_the_stream_comes_to_rest_anyway(state: dict) -> None:
    log: list[tuple[Any, int]] = []
    _take_back(_ctrl(log, **state))
    assert log == []
