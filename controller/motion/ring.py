"""Shared-memory ring of reference-point rows (float64): generator process to motion process."""

from __future__ import annotations

import mmap
import time

import numpy as np

WRITE, READ, FLAGS, N_COLS, CAPACITY = range(5)
HEADER_WORDS = 8
FLAG_FINAL = 1  # the producer wrote its last row
FLAG_FAILED = 2  # the producer raised; the message travels on the runtime's error queue
FLAG_ABORT = 4  # the consumer stopped: producers must exit


class RefRing:
    """Single producer, single consumer; no per-sample pickling, rows are copied into shm.

    The producer writes rows, then publishes the new write count (x86 stores are not
    reordered, and each count is one aligned 8-byte word), so a reader never sees a
    half-written row. A full ring blocks the producer: that is the back-pressure.
    """

    def __init__(self, buf: mmap.mmap) -> None:
        self.buf = buf
        self.header = np.ndarray((HEADER_WORDS,), dtype=np.int64, buffer=buf)
        self.capacity = int(self.header[CAPACITY])
        self.n_cols = int(self.header[N_COLS])
        self.rows = np.ndarray((self.capacity, self.n_cols), dtype=np.float64,
                               buffer=buf, offset=HEADER_WORDS * 8)

    @classmethod
    def create(cls, capacity_rows: int, n_cols: int) -> RefRing:
        size = HEADER_WORDS * 8 + capacity_rows * n_cols * 8
        # An anonymous shared mapping (zero-filled): the producers are forked and inherit it,
        # and nobody attaches by name, so nothing is ever in /dev/shm, even when every process
        # of the run is killed together. A named SharedMemory also started multiprocessing's
        # resource tracker, a whole interpreter of its own (some 40 ms of CPU per run).
        buf = mmap.mmap(-1, size, flags=mmap.MAP_SHARED)
        header = np.ndarray((HEADER_WORDS,), dtype=np.int64, buffer=buf)
        header[N_COLS], header[CAPACITY] = n_cols, capacity_rows
        del header
        return cls(buf)

    # -- producer -------------------------------------------------------------------------
    def write(self, rows: np.ndarray, poll_s: float = 0.001) -> bool:
        """Copy rows in, waiting while the ring is full; False if the consumer aborted."""
        done = 0
        while done < len(rows):
            if self.flags & FLAG_ABORT:
                return False
            free = self.capacity - int(self.header[WRITE] - self.header[READ])
            if free <= 0:
                time.sleep(poll_s)
                continue
            n = min(free, len(rows) - done)
            w = int(self.header[WRITE])
            start = w % self.capacity
            first = min(n, self.capacity - start)  # up to the ring's end, the rest from 0
            self.rows[start : start + first] = rows[done : done + first]
            self.rows[: n - first] = rows[done + first : done + n]
            self.header[WRITE] = w + n  # publish after the copy
            done += n
        return True

    # -- consumer -------------------------------------------------------------------------
    def read(self, max_rows: int) -> np.ndarray:
        r = int(self.header[READ])
        n = max(0, min(max_rows, int(self.header[WRITE]) - r))
        start = r % self.capacity
        first = min(n, self.capacity - start)  # up to the ring's end, the rest from 0
        out = self.rows[start : start + first].copy()
        if first < n:
            out = np.concatenate((out, self.rows[: n - first]))
        self.header[READ] = r + n
        return out

    def available(self) -> int:
        return int(self.header[WRITE] - self.header[READ])

    @property
    def written(self) -> int:
        return int(self.header[WRITE])

    # -- flags ----------------------------------------------------------------------------
    @property
    def flags(self) -> int:
        return int(self.header[FLAGS])

    def set_flag(self, flag: int) -> None:
        # Each flag has one writer side (FINAL/FAILED producer, ABORT consumer); a lost
        # update between them is harmless because both ends stop on either.
        self.header[FLAGS] = int(self.header[FLAGS]) | flag

    def close(self) -> None:
        del self.header, self.rows
        self.buf.close()  # unmapped here; freed once the forked producers unmapped it too
