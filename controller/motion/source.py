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
    # (in the order of the marks); a source without it has none.

    # primed() -> bool, optional (a source without it is always primed): the buffer ahead of
    # the motion loop is full, or the producer has finished or failed. A job starts moving only
    # then, so that a loaded PC's generator starts with the whole buffer as its head start.


PAUSE_MARK, OUTPUT_MARK = 0.5, 0.25  # a marked row's line is -(line + mark)


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
    marked = np.flatnonzero(rows[:, -1] < 0.0)
    return int(marked[0]) if marked.size else None


def is_output_mark(value: float) -> bool:
    """A marked row's line value marks outputs (else a pause)."""
    return value < 0.0 and abs(-value - np.floor(-value) - OUTPUT_MARK) < 1e-6


def row_lines(rows: np.ndarray) -> np.ndarray:
    """The NC line of each row, marks removed."""
    line = rows[:, -1]
    return np.where(line < 0.0, np.floor(-line), line)


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
        rows = chunk_rows(chunk)
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
