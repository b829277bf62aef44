"""Work in blocks of frames: refills a block at a time, and virtual time clocked a block a cycle.

A cycle of two frames paid the loop's whole fixed cost (a refill through the re-timer, the
pre-compensation and the pulse counter; the checks; the sim card's servo step) for two rows:
at T = 1 ms that was a sixth of a core. Per cycle the loop now only reads the feedback, checks
it and watches the requests; it refills once the card has room for a block. In virtual time,
while the stream runs steadily, one cycle clocks the card a whole block (no more than the FIFO
holds above its low-water mark), and a fault inside the block is found where a loop clocking
two frames a cycle would have found it: the card takes the block back and clocks only to the
end of that cycle (SimCard.advance_until), so the stop starts from the same frame.
"""

from __future__ import annotations

import copy

import numpy as np

from controller.motion.checks import FerrorCheck, RefHistory
from controller.motion.feedback_check import FeedbackCheck
from controller.motion.recall import Sent
from controller.motion.retime import SERVO_MEMORY
from drivers.base import Feedback


def block_frames(
    block_ms: float, period_s: float, cycle_frames: int, low_frames: int, high_frames: int
) -> int:
    """Frames of a refill block and of a virtual-time cycle: block_ms in whole cycles, at most
    half the span between the water marks (a block never takes the FIFO near its low mark),
    at least one cycle."""
    want = int(round(block_ms * 1e-3 / period_s))
    span = max(cycle_frames, (high_frames - low_frames) // 2)
    return max(cycle_frames, min(want, span) // cycle_frames * cycle_frames)


def fault_rows(
    fb: Feedback, fbcheck: FeedbackCheck, ferr: FerrorCheck, hist: RefHistory
) -> int | None:
    """How many rows of a block's feedback a loop reading it cycle by cycle would have read
    when it first had to stop (a reading no drive could give, a following error), or None.
    The checks are run on copies: the loop runs them on the block again as it reads it."""
    if not len(fb):
        return None
    bad = None if fbcheck.corrupt else copy.copy(fbcheck).check(fb)
    believed = len(fb) if bad is None else int(np.searchsorted(fb.seq, bad.seq))
    trip = copy.copy(ferr).check(
        Feedback(fb.seq[:believed], fb.commanded_counts[:believed], fb.encoder_counts[:believed]),
        hist,
    )
    if trip is not None:
        return int(np.searchsorted(fb.seq, trip.seq)) + 1
    return None if bad is None else believed + 1


def journal_pieces(
    before: Sent, consumed: np.ndarray, counts: np.ndarray, precomp_marks: list[tuple], piece: int
) -> list[Sent]:
    """A send of whole rows as they are (the re-timer's identity) as the sends of `piece`
    frames a cycle would have made, each with the state before it, so that a take-back (an
    e-stop keeps two frames) undoes as much of a block as of cycle-sized sends. counts: the
    pulse counter after each row; precomp_marks: the pre-compensator's state after each
    piece but the last (Precompensator.push with every=piece)."""
    pos = consumed[:, : len(before.last_mm)]
    back, recent = before.retimer["back"], before.retimer["recent"]
    entries = []
    for j, start in enumerate(range(0, len(consumed), piece)):
        entry = (
            before
            if not start
            else Sent(
                0,
                consumed[:0],
                dict(
                    before.retimer,
                    back=np.vstack([back, consumed[:start]])[-SERVO_MEMORY:],
                    recent=np.vstack([recent, consumed[:start, :2]])[-SERVO_MEMORY:],
                ),
                pos[start - 2] if start >= 2 else before.last_mm,
                pos[start - 1],
                counts[start - 1],
                before.hist_count + start,
                None if before.precomp is None else precomp_marks[j - 1],
            )
        )
        entry.frames, entry.consumed = (
            min(piece, len(consumed) - start),
            consumed[start : start + piece],
        )
        entries.append(entry)
    return entries
