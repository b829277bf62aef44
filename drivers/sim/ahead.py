"""The real-time sim card's queued frames stepped a block ahead, handed out as they fall due."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import Feedback

AHEAD_FRAMES = 32  # frames stepped through the axes in one call (the host reads every 2)


@dataclass
class _Ahead:
    snap: tuple[np.ndarray, ...]  # the axes before the block
    seq: np.ndarray
    cmd: np.ndarray
    enc: np.ndarray
    released: int = 0  # rows handed out (their periods have come)

    @property
    def left(self) -> int:
        return len(self.seq) - self.released


class AheadClock:
    """Mixed into SimCard (its lock held in every method). In real time the frames at the
    FIFO's head, none ending the stream, are stepped through the axes AHEAD_FRAMES at a time;
    each catch-up hands out the rows whose periods have come, the rows the card would have
    clocked then: what a queued frame does cannot change while it waits, except by what
    first takes the block back (take_back_ahead: a recall, a reset, a disable, an injection,
    a homing, an output scheduled on a frame, a write that would reach the block's slots, an
    end of stream marked on it, a position read). The axes then go back to before the block
    and only the rows handed out are stepped again."""

    _ahead: _Ahead | None = None
    ahead_takebacks = 0  # blocks taken back so far: rows checked ahead of one are void

    def rows_ahead(self) -> tuple[int, Feedback] | None:
        """The block stepped ahead, all its rows (handed out or not) as the card numbers them,
        and ahead_takebacks now: the motion loop checks them once (motion/checked_ahead.py)."""
        card: Any = self
        with card._lock:
            ahead = self._ahead
            if ahead is None:
                return None
            return self.ahead_takebacks, Feedback(ahead.seq, ahead.cmd, ahead.enc)

    def queued_frames(self) -> int:
        """Frames whose periods have not come: the FIFO's and the block's left."""
        card: Any = self
        return len(card._fifo) + (self._ahead.left if self._ahead is not None else 0)

    def release_ahead(self, due: int) -> int:
        """Hand out up to `due` rows of the block (as clocked); returns how many."""
        ahead = self._ahead
        if ahead is None or due <= 0:
            return 0
        card: Any = self
        lo = ahead.released
        hi = lo + min(due, ahead.left)
        card._trace.append((ahead.seq[lo:hi], ahead.cmd[lo:hi], ahead.enc[lo:hi]))
        ahead.released = hi
        card._clocked += hi - lo
        if not ahead.left:
            self._ahead = None
        return hi - lo

    def clock_ahead(self) -> None:
        """Step the next block of queued frames, if there is no block and nothing a frame's
        own period must see (a halt, a homing, an output set as its frame is clocked)."""
        card: Any = self
        if (
            self._ahead is not None
            or card._status.halted
            or card._homing_run is not None
            or card.frame_outputs.waiting
        ):
            return
        n = card._fifo.before_end(AHEAD_FRAMES)
        if n < 2:
            return
        snap = card._axes.snapshot()
        frames, seq, _ = card._fifo.pop(n)
        cmd, enc = card._axes.step(frames)
        self._ahead = _Ahead(snap, seq, cmd, enc)

    def take_back_ahead(self) -> None:
        """The block's rows not handed out go back to the FIFO, unclocked."""
        ahead = self._ahead
        if ahead is None:
            return
        card: Any = self
        self._ahead = None
        self.ahead_takebacks += 1
        card._axes.restore(ahead.snap)
        card._fifo.unpop(len(ahead.seq))
        if ahead.released:
            frames, _, _ = card._fifo.pop(ahead.released)
            card._axes.step(frames)

    def ahead_span(self) -> int:
        """FIFO slots the block holds (a write must not reach them)."""
        return len(self._ahead.seq) if self._ahead is not None else 0
