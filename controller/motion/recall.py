"""Taking back frames queued in the card for a feed hold: what the loop has sent (SendState),
a journal of what each send changed, and the take-back that restores the state before them."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from controller.motion.checks import RefHistory
from controller.motion.pulses import PulseCounter
from controller.motion.retime import Retimer
from drivers.base import Drive
from drivers.errors import DriveError

JOURNAL_ENTRIES = 512  # sends remembered; more than a FIFO's worth at two frames a cycle
TAKE_BACK_TRIES = 3  # take-backs refused because the card clocked on meanwhile: tried again
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
    precomp: tuple | None = None  # the pre-compensator's state (None: not compensated)


class SendJournal:
    """What each send changed, newest last, so the newest sends can be undone together with
    the frames the card takes back (Drive.recall_frames). Arrays are kept by reference: the
    loop replaces them, never writes into them. A block sent as it is (motion/blocks.py) is
    kept whole and cut into its cycle-sized sends only when a take-back looks (rarely): the
    same entries, without making them for every block."""

    def __init__(self) -> None:
        self.entries: list[Any] = []  # Sent, or a block's Pieces not yet made
        self._count = 0  # the sends they hold

    def record(self, frames: int, consumed: np.ndarray, before: Sent) -> None:
        if frames <= 0:
            return
        before.frames, before.consumed = frames, consumed
        self._add(before, 1)

    def record_block(self, block: Any, piece: int) -> None:
        """A block's rows sent at once, journalled as sends of `piece` frames (BlockSend)."""
        if len(block.consumed):
            self._add(Pieces(block, piece), -(-len(block.consumed) // piece))

    def _add(self, entry: Any, count: int) -> None:
        self.entries.append(entry)
        self._count += count
        # The oldest go while the rest hold JOURNAL_ENTRIES sends; made() trims exactly.
        while len(self.entries) > 1 and self._count - _sends(self.entries[0]) >= JOURNAL_ENTRIES:
            self._count -= _sends(self.entries.pop(0))

    def made(self) -> list[Sent]:
        """Every entry a Sent (blocks cut into their sends), the newest JOURNAL_ENTRIES. A
        take-back whose drive level is read just before it calls this first: cutting a
        FIFO's worth of blocks takes a few hundred microseconds, in which the card clocks on."""
        if any(isinstance(e, Pieces) for e in self.entries):
            flat: list[Sent] = []
            for e in self.entries:
                flat.extend(e.made() if isinstance(e, Pieces) else (e,))
            self.entries = flat[-JOURNAL_ENTRIES:]
        elif len(self.entries) > JOURNAL_ENTRIES:
            del self.entries[: len(self.entries) - JOURNAL_ENTRIES]
        self._count = len(self.entries)
        return self.entries

    def clear(self) -> None:
        self.entries.clear()
        self._count = 0

    def newest_within(self, budget_frames: int) -> list[Sent]:
        """The newest sends whose frames add up to at most budget_frames, newest first."""
        out: list[Sent] = []
        total = 0
        for entry in reversed(self.made()):
            if total + entry.frames > budget_frames:
                break
            out.append(entry)
            total += entry.frames
        return out

    def drop(self, n: int) -> None:
        entries = self.made()
        del entries[len(entries) - n:]
        self._count = len(entries)


class Pieces:
    """A block's journal entries (BlockSend.pieces(piece)), made when first asked for."""

    def __init__(self, block: Any, piece: int) -> None:
        self.block, self.piece = block, piece
        self.sends = -(-len(block.consumed) // piece)

    def made(self) -> list[Sent]:
        return self.block.pieces(self.piece)  # type: ignore[no-any-return]


def _sends(entry: Any) -> int:
    return entry.sends if isinstance(entry, Pieces) else 1


def retimer_state(retimer: Retimer) -> dict[str, Any]:
    state = {name: getattr(retimer, name) for name in RETIMER_FIELDS}
    state["ramp"] = copy.copy(state["ramp"])
    return state


def restore_retimer(retimer: Retimer, state: dict[str, Any]) -> None:
    for name, value in state.items():
        setattr(retimer, name, value)


class Compensator(Protocol):
    """The servo pre-compensator as a take-back sees it: its state saved and put back."""

    def state(self) -> tuple: ...

    def restore(self, state: tuple) -> None: ...


@dataclass
class SendState:
    """What the motion loop has read and sent, all that a take-back restores: the reference
    rows held (read, not sent), the last two points sent, the frame count, and the parts
    whose state each send changes (re-timer, pulse counter, reference history, pre-
    compensator). The loop owns one; only it and take_back write it."""

    held: np.ndarray  # rows (position, feed, line) read from the source, not sent yet
    prev_mm: np.ndarray
    last_mm: np.ndarray
    retimer: Retimer
    pulses: PulseCounter
    hist: RefHistory
    precomp: Compensator | None  # None: not pre-compensated
    sent: int = 0  # frames sent
    recalled_frames: int = 0  # frames taken back from the card
    journal: SendJournal = field(default_factory=SendJournal)

    def before_send(self) -> Sent:
        """The state a send starts from (its frames and rows filled in by the journal)."""
        return Sent(0, self.held[:0], retimer_state(self.retimer), self.prev_mm, self.last_mm,
                    self.pulses.counts, self.hist.count,
                    None if self.precomp is None else self.precomp.state())

    def backlog(self, level: int, keep_frames: int) -> list[Sent]:
        """The sends a take-back keeping keep_frames of `level` queued would undo, newest
        first (empty: none)."""
        return self.journal.newest_within(level - keep_frames)

    def held_after(self, undo: list[Sent]) -> np.ndarray:
        """The held rows once `undo` is taken back: its rows read again, then those held."""
        return np.vstack([e.consumed for e in reversed(undo)] + [self.held])

    def take_back(self, drive: Drive, level: int, keep_frames: int,
                  undo: list[Sent] | None = None) -> int:
        """A hold, a lower override or an e-stop: take back the frames queued beyond
        keep_frames (where the drive can), undoing their sends, so the new ramp starts there
        instead of behind the whole FIFO. The ramp is planned from the state restored.
        undo: the sends to undo (backlog(), found before), else those beyond keep_frames of
        `level`. Returns the frames taken back (0: none, nothing changed)."""
        undo = self.backlog(level, keep_frames) if undo is None else undo
        total = sum(e.frames for e in undo)
        if not undo or drive.recall_frames(total, keep_frames) != total:
            return 0
        oldest = undo[-1]
        restore_retimer(self.retimer, oldest.retimer)
        self.prev_mm, self.last_mm = oldest.prev_mm, oldest.last_mm
        self.pulses.counts = oldest.counts
        self.hist.count = oldest.hist_count
        if self.precomp is not None:
            self.precomp.restore(oldest.precomp)  # type: ignore[arg-type]
        self.held = self.held_after(undo)
        self.sent -= total
        self.journal.drop(len(undo))
        self.recalled_frames += total
        return total

    def take_back_now(self, drive: Drive, keep_frames: int) -> int:
        """take_back from the level the drive reports now: an e-stop's or a probe trip's,
        which keep only a few frames. The journal's blocks are cut into sends first (a few
        hundred microseconds for a FIFO's worth), so the card does not clock on between the
        level's read and the take-back; one refused because the card clocked on anyway (the
        level fell below what it needed) is tried again from the level then, up to
        TAKE_BACK_TRIES times. A drive that cannot take back is asked once. Returns the
        frames taken back (0: none)."""
        self.journal.made()
        try:
            level = drive.fifo_level()
            for _ in range(TAKE_BACK_TRIES):
                undo = self.backlog(level, keep_frames)
                if not undo:
                    return 0
                got = self.take_back(drive, level, keep_frames, undo)
                if got:
                    return got
                level = drive.fifo_level()
                if level >= keep_frames + sum(e.frames for e in undo):
                    return 0  # they were still queued: the drive cannot take them back
        except DriveError:  # the link lost: the cycle's next read faults on it
            return 0
        return 0
