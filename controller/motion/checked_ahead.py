"""Real time: a block the card stepped ahead is checked once, not two frames every cycle.

The real-time sim card steps the frames at its FIFO's head through its axes a block at a time
and hands their rows out as their periods come (drivers/sim/ahead.py). Those rows are known
a block before the loop reads them, so their feedback and following-error checks run once on
the whole block (blocks.fault_rows, as a virtual-time block's). While the cycles then read
exactly those rows, from a block not taken back since, they take the checks as passed: the
checks' objects lag behind (caught up on demand: a progress report, the result, a cycle that
leaves the block) and the state after the whole block is put in place when its last row is
read. A block in which a check fails is not planned: its cycles check their rows as before,
so a fault acts at the cycle it did. The cycle-by-cycle checks give the same results on rows
however they are cut (a cycle's two rows or a whole block), which is what lets a block's
result stand for its cycles'.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from controller.motion.checks import RefHistory
from drivers.base import Feedback

RowsAhead = Callable[[], "tuple[int, Feedback] | None"]


class _Plan:
    """A block's rows checked ahead: raw (the card's numbering), the checks after them, the
    card's take-back count then, how many rows the cycles have read and the checks applied."""

    __slots__ = ("rows", "after", "takebacks", "read", "applied")

    def __init__(self, rows: Feedback, after: tuple[Any, Any], takebacks: int) -> None:
        self.rows, self.after, self.takebacks = rows, after, takebacks
        self.read = self.applied = 0


class AheadPlan:
    """The loop's checks (RunChecks: fbcheck, ferr) over blocks stepped ahead (module doc)."""

    def __init__(
        self,
        checks: Any,
        hist: RefHistory,
        own: Callable[[Feedback], Feedback],
        drive: Any,
        fault_rows: Callable[..., tuple[int | None, Any]],
    ) -> None:
        self.checks, self.hist, self.own = checks, hist, own
        self.drive = drive
        self._rows_ahead: RowsAhead | None = getattr(drive, "rows_ahead", None)
        self._fault_rows = fault_rows
        self._plan: _Plan | None = None
        self._refused: tuple[int, int] | None = None  # (take-backs, first seq): a block failed
        self.cycles_taken = 0  # cycles whose rows were checked ahead (tests, benches)

    def take(self, raw: Feedback) -> bool:
        """Whether raw (a cycle's rows) are the next rows of the planned block: then they
        stand checked. Otherwise the checks are caught up and the plan dropped."""
        plan = self._plan
        if plan is None:
            return False
        n, at = len(raw), plan.read
        rows = plan.rows
        if (
            at + n <= len(rows)
            and getattr(self.drive, "ahead_takebacks", -1) == plan.takebacks
            and (not n or int(raw.seq[0]) == int(rows.seq[at]))
            and np.array_equal(raw.encoder_counts, rows.encoder_counts[at : at + n])
            and np.array_equal(raw.commanded_counts, rows.commanded_counts[at : at + n])
        ):
            plan.read = at + n
            if plan.read == len(rows):  # the block's last row: the checks as after it
                self.checks.fbcheck, self.checks.ferr = plan.after
                self._plan = None
            self.cycles_taken += 1
            return True
        self.catch_up()
        self._plan = None
        return False

    def catch_up(self) -> None:
        """The checks' objects brought to the last row read (rows that passed ahead)."""
        plan = self._plan
        if plan is None or plan.applied == plan.read:
            return
        lo, hi = plan.applied, plan.read
        rows = self.own(Feedback(*(a[lo:hi] for a in _parts(plan.rows))))
        self.checks.fbcheck.check(rows)
        self.checks.ferr.check(rows, self.hist)
        plan.applied = hi

    def plan_next(self) -> None:
        """After a cycle checked its own rows: check the card's block ahead, from the row
        after the last one read, if it starts there (nothing read first from elsewhere)."""
        fbcheck = self.checks.fbcheck
        if (
            self._plan is not None
            or self._rows_ahead is None
            or fbcheck.corrupt
            or fbcheck.last_seq < 0
        ):  # (nothing read yet: the run's numbering not known)
            return
        got = self._rows_ahead()
        if got is None:
            return
        takebacks, block = got
        own = self.own(block)
        start = int(np.searchsorted(own.seq, fbcheck.last_seq, side="right"))
        if start >= len(own) or int(own.seq[start]) != fbcheck.last_seq + 1:
            return
        key = (takebacks, int(block.seq[0]))
        if key == self._refused:  # a fault ahead: its cycles check their rows themselves
            return
        ahead = Feedback(*(a[start:] for a in _parts(own)))
        _, after = self._fault_rows(ahead, fbcheck, self.checks.ferr, self.hist)
        if after is None:
            self._refused = key
            return
        self._plan = _Plan(Feedback(*(a[start:] for a in _parts(block))), after, takebacks)


def _parts(fb: Feedback) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return fb.seq, fb.commanded_counts, fb.encoder_counts
