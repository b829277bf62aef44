"""A fault during a stop (abort, feed hold, program end) ends the run as a fault that names both
what was asked and what happened (it was recorded as the abort, and cncd went IDLE)."""

from __future__ import annotations

from refgen import circle_chunks, line_chunks
from test_motion import run

from controller.motion.loop import MotionController
from controller.motion.types import Outcome


def test_a_drive_fault_during_an_abort_is_a_fault_naming_both() -> None:
    def inject(card: object, ctrl: MotionController, _: object) -> None:
        ctrl.request_abort("aborted by operator")
        ctrl._cycle()  # the abort's stop is now under way
        assert ctrl.outcome is Outcome.ABORTED
        card.inject_drive_fault(0, 0x2310)  # type: ignore[attr-defined]
    result, _, _, _ = run(list(circle_chunks()), inject=inject)
    assert result.outcome is Outcome.FAULT
    assert result.message == "aborted by operator; then X axis drive fault 0x2310"


def test_a_following_error_during_an_abort_is_a_fault_naming_both() -> None:
    def inject(card: object, ctrl: MotionController, _: object) -> None:
        ctrl.request_abort("aborted by operator")
        ctrl._cycle()
        card.inject_stall(1)  # type: ignore[attr-defined]
    result, _, _, _ = run(list(circle_chunks()), inject=inject)
    assert result.outcome is Outcome.FAULT
    assert result.message.startswith("aborted by operator; then Y axis following error")


def test_a_drive_fault_during_a_feed_hold_says_the_hold() -> None:
    def inject(card: object, ctrl: MotionController, _: object) -> None:
        ctrl.request_hold()
        ctrl._cycle()
        card.inject_drive_fault(1, 0x2310)  # type: ignore[attr-defined]
    result, _, _, _ = run(list(circle_chunks()), inject=inject)
    assert result.outcome is Outcome.FAULT
    assert result.message.startswith("feed hold at line ")
    assert result.message.endswith("; then Y axis drive fault 0x2310")


def test_a_drive_fault_while_settling_at_the_program_end_says_the_end() -> None:
    def inject(card: object, ctrl: MotionController, _: object) -> None:
        if not ctrl.sent_eos:
            ctrl._injected = 0  # type: ignore[attr-defined]  (again at the next report)
            return
        card.inject_drive_fault(0, 0x2310)  # type: ignore[attr-defined]
    result, _, _, _ = run(list(line_chunks((2.0, 0.0))), inject=inject, at_s=0.0)
    assert result.outcome is Outcome.FAULT
    assert result.message == "program end; then X axis drive fault 0x2310"
