"""Reference points: what the generator streams to the motion controller, a chunk at a time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False, repr=False)
class RefChunk:
    """Consecutive reference points, one row per sample period T.

    pos_mm has one column per configured axis, in the config's axis order (x, y[, z]).
    Sample i of the chunk is at time t0_s + i * T. line is the NC source line per sample.
    final marks the last chunk of the program: its last row is the programmed end point.
    pause_after marks a program pause (M0): the machine waits at rest after the last row until
    the operator resumes. outputs (OutputChange) are set when the machine, at rest, has reached
    the first row (controller/generator/output_marks.py). sync_outputs, on a chunk of no rows:
    (line, changes), set without a stop at the first sample of that line that follows (M62).
    """

    t0_s: float
    pos_mm: np.ndarray  # (N, n_axes)
    feed_mm_s: np.ndarray  # (N,)
    line: np.ndarray  # (N,) int32
    final: bool = False
    pause_after: bool = False
    outputs: tuple = ()
    sync_outputs: tuple = ()

    def __len__(self) -> int:
        return int(self.pos_mm.shape[0])
