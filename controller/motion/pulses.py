"""Reference points to per-sample integer pulse counts, with the remainder carried (no drift)."""

from __future__ import annotations

import numpy as np


class PulseCounter:
    """Turns absolute positions into pulse frames whose running sum is round(pos / pulse_mm).

    Rounding the absolute position (not each increment) is what makes drift impossible: the
    accumulated pulses after any frame equal the rounded latest commanded position exactly.
    """

    def __init__(self, pulse_mm: np.ndarray, start_counts: np.ndarray) -> None:
        self.pulse_mm = np.asarray(pulse_mm, dtype=float)
        self.counts = np.asarray(start_counts, dtype=np.int64).copy()
        self.start_counts = self.counts.copy()

    def frames(self, pos_mm: np.ndarray) -> np.ndarray:
        """Pulse frames (N, n_axes) int64 for positions (N, n_axes), vectorised over the chunk."""
        pos = np.asarray(pos_mm, dtype=float)
        if pos.shape[0] == 0:
            return np.zeros((0, self.counts.shape[0]), dtype=np.int64)
        absolute = np.rint(pos / self.pulse_mm).astype(np.int64)
        frames = np.empty_like(absolute)  # np.diff with prepend, without its joined copy
        np.subtract(absolute[0], self.counts, out=frames[0])
        np.subtract(absolute[1:], absolute[:-1], out=frames[1:])
        self.counts = absolute[-1].copy()
        return frames

    @property
    def commanded_counts(self) -> np.ndarray:
        """Pulses sent since start, per axis (signed)."""
        return self.counts - self.start_counts


def counts_of(pos_mm: np.ndarray, pulse_mm: np.ndarray) -> np.ndarray:
    """The pulse count of an absolute position (the rounding rule used everywhere)."""
    return np.rint(np.asarray(pos_mm, dtype=float) / pulse_mm).astype(np.int64)
