"""Where the motion controller reads reference points from: protocol plus an in-memory source."""

from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator
from typing import Protocol

import numpy as np

from controller.refpoints import RefChunk


class SourceState(enum.Enum):
    STREAMING = "streaming"  # more rows may come
    FINISHED = "finished"  # the producer wrote its final row (rows may still be unread)
    FAILED = "failed"  # the producer died or raised: no more rows will come


class RefSource(Protocol):
    """Rows are [pos_mm (n_axes)..., feed_mm_s, line] float64, one per sample period."""

    def read(self, max_rows: int) -> np.ndarray: ...

    def state(self) -> tuple[SourceState, str]: ...

    def total_rows(self) -> int | None: ...

    # next_outputs() -> tuple | None, optional: the OutputChanges of the next output mark read
    # (in the order of the marks); a source without it has none. next_sync_outputs() likewise
    # for the marks of M62/M63/M67 (set as the card clocks the marked row).

    # primed() -> bool, optional (a source without it is always primed): the buffer ahead of
    # the motion loop is full, or the producer has finished or failed. A job starts moving only
    # then, so that a loaded PC's generator starts with the whole buffer as its head start.


# A marked row's line is -(line + mark): a pause after it, outputs set at rest there, or
# outputs set as the card clocks it (M62/M63/M67, with the move; the loop takes that one off).
PAUSE_MARK, OUTPUT_MARK, SYNC_MARK = 0.5, 0.25, 0.125


def chunk_rows(chunk: RefChunk) -> np.ndarray:
    """A RefChunk as ring rows. A pause (M0) after the chunk is its last row's line, negated:
    the rows keep their width, and a line number is never negative otherwise. Outputs set at
    the chunk's first row mark it the same way, with a quarter instead of a half."""
    rows = np.column_stack([chunk.pos_mm, chunk.feed_mm_s, chunk.line.astype(float)])
    if chunk.pause_after and len(rows):
        rows[-1, -1] = -abs(rows[-1, -1]) - PAUSE_MARK  # line 0 can pause too
    if chunk.outputs and len(rows):
        rows[0, -1] = -abs(rows[0, -1]) - OUTPUT_MARK
    return rows


def pause_index(rows: np.ndarray) -> int | None:
    """The first row after which the program pauses or sets outputs, if any."""
    negative = rows[:, -1] < 0.0
    if not negative.any():  # no mark at all (most reads): one test, not the mark's seven calls
        return None
    marked = np.flatnonzero(negative & ~_is_mark(rows[:, -1], SYNC_MARK))
    return int(marked[0]) if marked.size else None


def sync_marked(rows: np.ndarray) -> np.ndarray:
    """The indices of the rows marked to set outputs as they are clocked (M62)."""
    if not len(rows) or not (rows[:, -1] < 0.0).any():  # (as pause_index: no mark)
        return _NONE
    return np.flatnonzero(_is_mark(rows[:, -1], SYNC_MARK))


_NONE = np.zeros(0, int)
_NONE.flags.writeable = False


def _is_mark(value: np.ndarray, mark: float) -> np.ndarray:
    neg = -value
    return (value < 0.0) & (np.abs(neg - np.floor(neg) - mark) < 1e-6)


def is_output_mark(value: float) -> bool:
    """A marked row's line value marks outputs (else a pause)."""
    return value < 0.0 and abs(-value - np.floor(-value) - OUTPUT_MARK) < 1e-6


def row_lines(rows: np.ndarray) -> np.ndarray:
    """The NC line of each row, marks removed."""
    line = rows[:, -1]
    return np.where(line < 0.0, np.floor(-line), line)


class SyncMarks:
    """The producer's side of M62: a chunk of no rows names a line (RefChunk.sync_outputs); the
    first row of that line in the chunks after it gets the mark, and its changes are handed
    on before those rows (the motion loop takes them in that order)."""

    def __init__(self) -> None:
        self.waiting: list[tuple[int, tuple]] = []

    def rows(self, chunk: RefChunk) -> tuple[np.ndarray, list[tuple]]:
        """The chunk's ring rows with their marks, and the changes of the marks set in them."""
        if chunk.sync_outputs:
            self.waiting.append(chunk.sync_outputs)
        rows = chunk_rows(chunk)
        marked: list[tuple] = []
        while self.waiting and len(rows):
            line, changes = self.waiting[0]
            hit = np.flatnonzero(chunk.line == line)
            if not hit.size:
                break
            k = int(hit[0])
            rows[k, -1] = -abs(float(chunk.line[k])) - SYNC_MARK
            marked.append(changes)
            self.waiting.pop(0)
        return rows, marked


class ChunkSource:
    """In-process source over an iterable of RefChunks (tests, `--virtual-time` single process).

    Test hooks: starve_after_rows (then STREAMING with no rows, a late generator) and
    fail_after_rows (then FAILED, a dead generator).
    """

    def __init__(self, chunks: Iterable[RefChunk], starve_after_rows: int | None = None,
                 fail_after_rows: int | None = None) -> None:
        self._chunks: Iterator[RefChunk] = iter(chunks)
        self._pending = np.zeros((0, 0))
        self._done = False
        self._read = 0
        self._starve = starve_after_rows
        self._fail = fail_after_rows
        self._error = ""
        self._outputs: list[tuple] = []
        self._sync_outputs: list[tuple] = []
        self._marks = SyncMarks()

    def next_sync_outputs(self) -> tuple | None:
        """The changes of the next M62 mark read (in stream order)."""
        return self._sync_outputs.pop(0) if self._sync_outputs else None

    def next_outputs(self) -> tuple | None:
        """The changes of the next output mark (in stream order), None when not yet read."""
        return self._outputs.pop(0) if self._outputs else None

    def read(self, max_rows: int) -> np.ndarray:
        limit = min(x for x in (self._starve, self._fail, 1 << 62) if x is not None)
        max_rows = max(0, min(max_rows, limit - self._read))
        while len(self._pending) < max_rows and not self._done and not self._error:
            self._pull()
        rows, self._pending = self._pending[:max_rows], self._pending[max_rows:]
        self._read += len(rows)
        return rows

    def _pull(self) -> None:
        try:
            chunk = next(self._chunks)
        except StopIteration:
            self._done = True
            return
        except Exception as exc:  # noqa: BLE001  (a producer failure becomes FAILED, reported)
            self._error = f"reference generator failed: {exc}"
            return
        rows, synced = self._marks.rows(chunk)
        self._sync_outputs += synced
        if chunk.outputs:
            self._outputs.append(chunk.outputs)
        self._pending = rows if not len(self._pending) else np.vstack([self._pending, rows])
        self._done = self._done or chunk.final

    def state(self) -> tuple[SourceState, str]:
        if self._error:
            return SourceState.FAILED, self._error
        if self._fail is not None and self._read >= self._fail:
            return SourceState.FAILED, "reference generator process died"
        if self._done and not len(self._pending):
            return SourceState.FINISHED, ""
        return SourceState.STREAMING, ""

    def total_rows(self) -> int | None:
        return self._read + len(self._pending) if self._done else None

    def primed(self) -> bool:
        return True  # in-process: the rows are produced when read
