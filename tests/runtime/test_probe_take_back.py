"""A probe's trip takes the card's frames back even when the card clocks on meanwhile."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from controller.motion.types import MotionState
from controller.runtime.probe_run import PROBE_KEEP_FRAMES, _take_back


class _Stream:
    """take_back refused (0) `refusals` times, as a drive that clocked a frame between the
    level's read and the take-back does; the journal made before any level is read."""

    def __init__(self, refusals: int, log: list[str]) -> None:
        self.refusals, self.log = refusals, log
        self.journal = SimpleNamespace(made=lambda: log.append("made"))

    def take_back(self, drive: Any, level: int, keep: int) -> int:
        self.log.append(f"take_back {level} {keep}")
        if self.refusals:
            self.refusals -= 1
            return 0
        return level - keep


def _ctrl(refusals: int, log: list[str]) -> Any:
    levels = iter((94, 93, 92, 91))

    def level() -> int:
        log.append("level")
        return next(levels)
    return SimpleNamespace(state=MotionState.RUNNING, sent_eos=False, pausing=False,
                           pending_tail=None, stream=_Stream(refusals, log),
                           drive=SimpleNamespace(fifo_level=level))


def test_a_refused_take_back_is_tried_again_from_the_level_then() -> None:
    log: list[str] = []
    _take_back(_ctrl(1, log))
    k = PROBE_KEEP_FRAMES
    assert log == ["made", "level", f"take_back 94 {k}", "level", f"take_back 93 {k}"]


def test_a_take_back_that_succeeds_is_not_repeated() -> None:
    log: list[str] = []
    _take_back(_ctrl(0, log))
    assert log == ["made", "level", f"take_back 94 {PROBE_KEEP_FRAMES}"]
