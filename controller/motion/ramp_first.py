"""A slower feed (a hold, a lower override) planned before the card's frames are taken back: the
ramp is planned from where the card will be once planned, then the take-back and the ramp's
write follow back to back."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from controller.errors import DriveError
from controller.motion.recall import SendState, Sent, restore_retimer, retimer_state
from drivers.base import Drive

# Kept queued in the card by the take-back itself. Between the take-back and the ramp's write
# the loop only interpolates the planned ramp and pre-compensates it (about 0.5 ms of CPU,
# where planning it took 1-2 ms more); what is kept covers a descheduling there (and, on the
# sim card, its clock thread catching up). Through cncd at load 7, 3 ms ran the card dry in 2
# holds of 34 (bench/holds_under_load.py); 6 ms in none of 120 at load 3-7.
HOLD_KEEP_MS = 6.0
# The card runs this much while the ramp is planned (about a millisecond of CPU: the servo
# model's check). The ramp is planned from the frame that far beyond what is kept; a plan
# that took longer finds fewer frames queued than it needs, takes nothing back and is planned
# again from further on (twice the budget, then four times).
PLAN_BUDGET_MS = 2.0
PLAN_TRIES = 3


def take_back_planned(
    stream: SendState,
    drive: Drive,
    level: int,
    rate: float,
    keep_frames: int,
    budget_frames: int,
    read_ahead: Callable[[], None],
) -> int:
    """The re-timer's ramp to `rate` planned from where the card will be after keep_frames
    plus budget_frames, then the frames queued beyond that taken back and the re-timer set
    to the ramp planned. Returns the FIFO level after it; nothing taken back (the drive
    cannot, each try overran its budget): the ramp starts behind all that is queued."""
    read_ahead()  # the ramp looks at the rows it will cross (Retimer.take reads them too)
    for attempt in range(PLAN_TRIES):
        undo = stream.backlog(level, keep_frames + (budget_frames << attempt))
        if not undo:
            return level
        planned = _planned_state(stream, undo, rate)
        got = stream.take_back(drive, level, keep_frames, undo)
        if got:
            restore_retimer(stream.retimer, planned)
            return level - got
        try:
            now = drive.fifo_level()
        except DriveError:  # the link lost: the cycle's next read faults on it
            return level
        if now >= keep_frames + sum(e.frames for e in undo):
            return now  # they were queued: the drive cannot take them back
        level = now
    return level


def _planned_state(stream: SendState, undo: list[Sent], rate: float) -> dict:
    """The re-timer's state once `undo` is taken back and its ramp to `rate` planned (what
    the next take() would find and plan); the re-timer itself left as it is."""
    retimer = stream.retimer
    now = retimer_state(retimer)
    held: np.ndarray = stream.held_after(undo)
    try:
        restore_retimer(retimer, undo[-1].retimer)
        retimer.set_target(rate)
        retimer.plan(held)
        return retimer_state(retimer)
    finally:
        restore_retimer(retimer, now)
