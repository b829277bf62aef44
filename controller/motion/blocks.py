"""Work in blocks of frames: refills a block at a time, and virtual time clocked a block a cycle.

A cycle of two frames paid the loop's whole fixed cost (a refill through the re-timer, the
pre-compensation and the pulse counter; the checks; the sim card's servo step) for two rows:
at T = 1 ms that was a sixth of a core. Per cycle the loop now only reads the feedback, checks
it and watches the requests; it refills once the card has room for a block. In virtual time,
while the stream runs steadily, one cycle clocks the card a whole block (no more than the FIFO
holds above its low-water mark), and a fault inside the block is found where a loop clocking
two frames a cycle would have found it: the card takes the block back and clocks only to the
end of that cycle (SimCard.advance_until), so the stop begins at the same cycle. A fault's
stop is queued behind what the card holds: with up to a block less queued, it ends up to a
block sooner along the same path than cycle by cycle (an e-stop or a hold takes the queue
back either way, see BlockSend).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np

from controller.motion.checked_ahead import AheadPlan
from controller.motion.checks import FerrorCheck, RefHistory
from controller.motion.feedback_check import FeedbackCheck
from controller.motion.recall import Sent
from controller.motion.retime import SERVO_MEMORY
from controller.servo.precompensation import Precompensator
from drivers.base import Feedback


def block_frames(block_ms: float, period_s: float, cycle_frames: int, span_frames: int) -> int:
    """Frames of a block: block_ms in whole cycles, at most span_frames (a block clocked from
    the high-water mark must not take the FIFO below its low one), at least one cycle."""
    want = min(int(round(block_ms * 1e-3 / period_s)), span_frames)
    return max(cycle_frames, want // cycle_frames * cycle_frames)


def fault_rows(
    fb: Feedback, fbcheck: FeedbackCheck, ferr: FerrorCheck, hist: RefHistory
) -> tuple[int | None, tuple[FeedbackCheck, FerrorCheck] | None]:
    """How many rows of a block's feedback a loop reading it cycle by cycle would have read
    when it first had to stop (a reading no drive could give, a following error), or None;
    and, when every row passed both, the two checks as they stand after the block. The checks
    are run on copies: the loop takes these copies in place of checking the block again."""
    if not len(fb):
        return None, None
    fb_copy, ferr_copy = _shallow(fbcheck), _shallow(ferr)
    bad = None if fbcheck.corrupt else fb_copy.check(fb)
    believed = len(fb) if bad is None else int(np.searchsorted(fb.seq, bad.seq))
    trip = ferr_copy.check(
        Feedback(fb.seq[:believed], fb.commanded_counts[:believed], fb.encoder_counts[:believed]),
        hist,
    )
    if trip is not None:
        return int(np.searchsorted(fb.seq, trip.seq)) + 1, None
    if bad is not None:
        return believed + 1, None
    return None, None if fbcheck.corrupt else (fb_copy, ferr_copy)


def _shallow(obj: Any) -> Any:
    """copy.copy of a check (a quarter of the cost: no __reduce_ex__ round): its arrays are
    replaced, never written in place, by checking, so the copy's checks leave obj's alone."""
    new = object.__new__(type(obj))
    new.__dict__.update(obj.__dict__)
    return new


class CheckedAhead:
    """The feedback and following-error checks of a virtual-time block, run once: the block's
    cut (fault_rows) checks its rows; if none failed, the cycle that then reads the same rows
    (the same arrays: the card hands the block out as it gave it to the cut) takes the checks
    as they stand after them instead of running both on them again. The card, halted or not
    after the block, changes neither result: a halt only widens the steps believed."""

    def __init__(
        self, checks: Any, hist: RefHistory, own: Callable[[Feedback], Feedback], drive: Any = None
    ) -> None:
        self.checks, self.hist, self.own = checks, hist, own  # the loop's (own: its numbers)
        self._rows: np.ndarray | None = None
        self._after: tuple[FeedbackCheck, FerrorCheck] | None = None
        # Real time: the card's blocks stepped ahead, checked once (motion/checked_ahead.py).
        self.plan = AheadPlan(checks, hist, own, drive, fault_rows)

    def cut(self, raw: Feedback) -> int | None:
        """fault_rows on a block as the card numbers it (the wait_block cut)."""
        c = self.checks
        rows, self._after = fault_rows(self.own(raw), c.fbcheck, c.ferr, self.hist)
        self._rows = raw.encoder_counts if self._after is not None else None
        return rows

    def believed(self, raw: Feedback, settling: bool) -> tuple[Feedback, Any, bool]:
        """FeedbackCheck.believed on a cycle's rows, and whether they were the block checked
        ahead, or rows of a real-time block checked ahead (then both checks stand as after
        them: the cycle checks nothing again). A halt (settling) only widens the steps
        believed: rows that passed without it pass with it."""
        done = self._after is not None and raw.encoder_counts is self._rows
        if done:
            self.checks.fbcheck, self.checks.ferr = self._after
        self._rows = self._after = None
        if done or self.plan.take(raw):
            return self.own(raw), None, True
        return (*self.checks.fbcheck.believed(self.own(raw), settling=settling), False)


class BlockSend:
    """A send of whole rows as they are (the re-timer's identity), journalled as the sends of
    `piece` frames a cycle would have made, so that a take-back (an e-stop keeps two frames)
    undoes as much of a block as of cycle-sized sends. The state before each piece is made
    only when a take-back asks for it (rarely): from the state before the block and the rows
    sent, as the cycle-sized sends would have left it."""

    def __init__(
        self, before: Sent, consumed: np.ndarray, counts: np.ndarray, precomp: Precompensator | None
    ) -> None:
        self.before, self.consumed, self.counts = before, consumed, counts
        self.precomp = precomp  # the loop's: copied before any use, never changed here

    def pieces(self, piece: int) -> list[Sent]:
        """The block's journal entries, oldest first (the first is the state before it)."""
        out: list[Sent] = []
        for start in range(0, len(self.consumed), piece):
            entry = self.before if not start else Piece(self, start)
            entry.frames = min(piece, len(self.consumed) - start)
            entry.consumed = self.consumed[start : start + piece]
            out.append(entry)  # type: ignore[arg-type]
        return out

    def state_at(self, start: int) -> dict[str, Any]:
        """What Sent holds for the piece starting at row `start` (> 0)."""
        b, rows = self.before, self.consumed[:start]
        pos = self.consumed[:, : len(b.last_mm)]
        retimer = dict(
            b.retimer,
            back=np.vstack([b.retimer["back"], rows])[-SERVO_MEMORY:],
            recent=np.vstack([b.retimer["recent"], rows[:, :2]])[-SERVO_MEMORY:],
        )
        return {
            "retimer": retimer,
            "prev_mm": pos[start - 2] if start >= 2 else b.last_mm,
            "last_mm": pos[start - 1],
            "counts": self.counts[start - 1],
            "hist_count": b.hist_count + start,
            "precomp": self._precomp_at(pos[:start]),
        }

    def _precomp_at(self, pos: np.ndarray) -> tuple | None:
        if self.precomp is None or self.before.precomp is None:
            return None
        comp = copy.copy(self.precomp)
        comp.stacked = copy.copy(comp.stacked)  # its matrices shared, its state its own
        comp.restore(self.before.precomp)
        comp.push(pos)
        return comp.state()


class Piece:
    """A journal entry of a BlockSend: frames and consumed rows now, the state on demand."""

    FIELDS = ("retimer", "prev_mm", "last_mm", "counts", "hist_count", "precomp")

    def __init__(self, block: BlockSend, start: int) -> None:
        self.block, self.start = block, start
        self.frames, self.consumed = 0, block.consumed[:0]

    def __getattr__(self, name: str) -> Any:
        if name not in Piece.FIELDS:
            raise AttributeError(name)
        for key, value in self.block.state_at(self.start).items():
            setattr(self, key, value)
        return getattr(self, name)
