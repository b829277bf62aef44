"""The simulated card's frame FIFO: a fixed-size numpy ring of pulse-count frames."""

from __future__ import annotations

import numpy as np

from drivers.errors import BadFrameError


class FrameFifo:
    """Single-producer single-consumer ring; each frame carries its stream sequence number."""

    def __init__(self, capacity_frames: int, n_axes: int) -> None:
        self.capacity = capacity_frames
        self._frames = np.zeros((capacity_frames, n_axes), dtype=np.int64)
        self._seq = np.zeros(capacity_frames, dtype=np.int64)
        self._eos = np.zeros(capacity_frames, dtype=bool)
        self._head = 0  # total frames ever popped or discarded
        self._tail = 0  # total frames ever pushed

    def __len__(self) -> int:
        return self._tail - self._head

    def push(self, frames: np.ndarray, first_seq: int, end_of_stream: bool) -> None:
        n = frames.shape[0]
        if len(self) + n > self.capacity:
            raise BadFrameError(f"card FIFO overflow: {len(self)} + {n} > {self.capacity} frames")
        idx = self._slots(self._tail, n)
        self._frames[idx] = frames
        self._seq[idx] = np.arange(first_seq, first_seq + n)
        self._eos[idx] = False
        if end_of_stream and n:
            self._eos[(self._tail + n - 1) % self.capacity] = True
        self._tail += n

    def _slots(self, first: int, n: int) -> slice | np.ndarray:
        """The ring's slots of n frames from frame `first`: a slice unless they wrap round its
        end (indexing by a slice costs a fraction of an index array's arange, modulo and
        gather; the same frames)."""
        start = first % self.capacity
        if start + n <= self.capacity:
            return slice(start, start + n)
        return np.arange(first, first + n) % self.capacity

    def mark_end(self) -> bool:
        """Flag the last queued frame as end of stream; False when nothing is queued."""
        if not len(self):
            return False
        self._eos[(self._tail - 1) % self.capacity] = True
        return True

    def recall(self, n: int, keep: int) -> int:
        """Take back the last n frames queued, if at least `keep` stay queued and none of them
        ends the stream; returns n, or 0 (nothing changed)."""
        if n <= 0 or len(self) - n < keep:
            return 0
        idx = np.arange(self._tail - n, self._tail) % self.capacity
        if self._eos[idx].any():
            return 0
        self._tail -= n
        return n

    def pop(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Up to n frames from the head: (frames, seq, eos flags)."""
        n = min(n, len(self))
        idx = self._slots(self._head, n)
        self._head += n
        return self._frames[idx].copy(), self._seq[idx].copy(), self._eos[idx].copy()

    def before_end(self, n: int) -> int:
        """How many of the next n frames (at most those queued) come before an end of stream."""
        n = min(n, len(self))
        ends = np.flatnonzero(self._eos[np.arange(self._head, self._head + n) % self.capacity])
        return int(ends[0]) if ends.size else n

    def unpop(self, n: int) -> None:
        """Put the last n frames popped back at the head (their slots are not reused until a
        push, so a block stepped ahead can be taken back before the next write)."""
        self._head -= n

    def clear(self) -> np.ndarray:
        """Discard everything queued; returns the discarded pulse sums per axis."""
        frames, _, _ = self.pop(len(self))
        return frames.sum(axis=0)
