"""Taking back frames queued in the card for a feed hold: a journal of what each send changed."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

JOURNAL_ENTRIES = 512  # sends remembered; more than a FIFO's worth at two frames a cycle
RETIMER_FIELDS = ("rate", "target", "wanted", "ramp", "frac", "back", "recent", "rows_passed",
                  "cap_at", "cap_goal", "cap_wanted")


@dataclass
class Sent:
    """One send: its frame count, the reference rows it consumed, and the state before it."""

    frames: int
    consumed: np.ndarray
    retimer: dict[str, Any]
    prev_mm: np.ndarray
    last_mm: np.ndarray
    counts: np.ndarray  # the pulse counter's
    hist_count: int
    precomp: Any = None  # the pre-compensator's state (None: not compensated)


class SendJournal:
    """What each send changed, newest last, so the newest sends can be undone together with
    the frames the card takes back (Drive.recall_frames). Arrays are kept by reference: the
    loop replaces them, never writes into them."""

    def __init__(self) -> None:
        self.entries: list[Sent] = []

    def record(self, frames: int, consumed: np.ndarray, before: Sent) -> None:
        if frames <= 0:
            return
        before.frames, before.consumed = frames, consumed
        self.entries.append(before)
        if len(self.entries) > JOURNAL_ENTRIES:
            del self.entries[: len(self.entries) - JOURNAL_ENTRIES]

    def clear(self) -> None:
        self.entries.clear()

    def newest_within(self, budget_frames: int) -> list[Sent]:
        """The newest sends whose frames add up to at most budget_frames, newest first."""
        out: list[Sent] = []
        total = 0
        for entry in reversed(self.entries):
            if total + entry.frames > budget_frames:
                break
            out.append(entry)
            total += entry.frames
        return out

    def drop(self, n: int) -> None:
        del self.entries[len(self.entries) - n:]


def retimer_state(retimer: Any) -> dict[str, Any]:
    state = {name: getattr(retimer, name) for name in RETIMER_FIELDS}
    state["ramp"] = copy.copy(state["ramp"])
    return state


def restore_retimer(retimer: Any, state: dict[str, Any]) -> None:
    for name, value in state.items():
        setattr(retimer, name, value)


def take_back(loop: Any, level: int, keep_frames: int | None = None) -> None:
    """A hold or a lower override on a MotionController: take back the frames queued beyond
    the low-water mark (where the drive can), undoing their sends, so the new ramp starts
    there instead of behind the whole FIFO. The ramp is planned from the state restored.
    keep_frames: fewer frames kept than the low-water mark (the e-stop's)."""
    keep = loop._frames(loop.settings.low_water_ms) if keep_frames is None else keep_frames
    undo = loop.journal.newest_within(level - keep)
    total = sum(e.frames for e in undo)
    if not undo or loop.drive.recall_frames(total, keep) != total:
        return
    oldest = undo[-1]
    restore_retimer(loop.retimer, oldest.retimer)
    loop.prev_mm, loop.last_mm = oldest.prev_mm, oldest.last_mm
    loop.pulses.counts = oldest.counts
    loop.hist.count = oldest.hist_count
    if loop.precomp is not None:
        loop.precomp.restore(oldest.precomp)
    loop.sent -= total
    loop.held = np.vstack([e.consumed for e in reversed(undo)] + [loop.held])
    loop.journal.drop(len(undo))
    loop.recalled_frames += total
