"""How a run's stops end otherwise than planned: a fault during a stop, and the e-stop (a
category 1 stop: the fastest stop the drives allow, along the path, then the drives disabled)."""

from __future__ import annotations

from typing import Any

from controller.errors import CncError
from controller.motion.recall import take_back
from controller.motion.stopping import amax_stop_distances_mm, stop_along_path
from controller.motion.types import MotionState, Outcome

ESTOP_INPUT = "e-stop input on the drive tripped"
ESTOP_KEEP_FRAMES = 2  # frames left in the card when the e-stop takes the rest back


def asked(ctrl: Any) -> str:
    """The stop under way when nothing went wrong yet (a fault then names it too)."""
    if ctrl.holding:
        return f"feed hold at line {ctrl.line}"
    if ctrl.pausing:
        return f"program pause at line {ctrl.line}"
    return "program end" if ctrl.sent_eos else ""


def then_fault(ctrl: Any, message: str) -> None:
    """A fault during a stop (abort, e-stop, hold, program end) is a fault: it says what was
    asked and what happened (an abort's fault was reported as an abort, and the daemon went
    IDLE on a faulted drive)."""
    before = ctrl.message if ctrl.outcome is not None else asked(ctrl)
    if before and message in before:
        return
    ctrl.outcome = Outcome.FAULT
    ctrl.message = f"{before}; then {message}" if before else message


def check(ctrl: Any, level: int) -> None:
    """Each cycle: an e-stop asked, or the drive's e-stop input open, starts the e-stop once."""
    if ctrl.estop_reason is not None:
        return
    reason = ctrl.estop_message
    if reason is None and ctrl.drive.estop_input():
        reason = ESTOP_INPUT
    if reason is not None:
        ctrl.estop_reason = reason
        _begin(ctrl, reason, level)


def _begin(ctrl: Any, reason: str, level: int) -> None:
    if ctrl.outcome is None or ctrl.outcome is Outcome.DONE:
        ctrl.outcome, ctrl.message = Outcome.ABORTED, reason
    elif reason not in ctrl.message:
        ctrl.message = f"{ctrl.message}; then {reason}"
    if not ctrl.sent:
        ctrl.state = MotionState.FINISHED  # nothing moved
        return
    accel = ctrl.config.interpolator.max_accel_mm_s2
    if ctrl.state is MotionState.STOPPING:
        # An abort's stop: its rows not yet sent are re-timed at Amax along themselves. Once
        # all are sent (the stream has ended) nothing is added: the card stops where they end.
        if len(ctrl.pending_stop) and not ctrl.sent_eos:
            ctrl.pending_stop = stop_along_path(ctrl.prev_mm, ctrl.last_mm, ctrl.pending_stop,
                                                accel, ctrl.period_s, amax_stop_distances_mm)
        return
    ends_at_rest = ctrl.sent_eos or ctrl.pausing or ctrl.pending_tail is not None
    if ctrl.state in (MotionState.WAITING, MotionState.RUNNING) and not ends_at_rest:
        # The frames queued beyond a couple are taken back (where the drive can): the stop
        # starts 2 ms out instead of behind the whole FIFO.
        take_back(ctrl, level, keep_frames=ESTOP_KEEP_FRAMES)
        ctrl.pending_stop = stop_along_path(ctrl.prev_mm, ctrl.last_mm,
                                            ctrl.held[:, : ctrl.n], accel, ctrl.period_s,
                                            amax_stop_distances_mm)
        ctrl.held = ctrl.held[:0]
        ctrl.state = MotionState.STOPPING
        return
    if ctrl.state in (MotionState.PAUSED, MotionState.HELD, MotionState.RUNNING):
        # At rest, or coming to rest where the stream ends: settle there, then disable.
        ctrl.state = MotionState.SETTLING
        ctrl.settle_deadline_s = ctrl.pacer.elapsed_s() + ctrl.settings.settle_s


def disable_drives(ctrl: Any) -> None:
    """After the e-stop's stop: the drives disabled (a failure to is a fault, named)."""
    if ctrl.estop_reason is None:
        return
    try:
        ctrl.drive.disable()
    except CncError as exc:
        then_fault(ctrl, f"the drives could not be disabled: {exc}")
