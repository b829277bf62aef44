"""Long blocks in bounded parts: a line or arc of hours, a long dwell, planned a piece at a time."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from controller.blocks import ArcBlock, LineBlock

# A contour line or arc whose nominal time (length over programmed feed) exceeds this is
# planned as parts of at most this: a look-ahead window holds whole blocks, and one arc of a
# million turns (LinuxCNC's G2 P) or a 100 mm line at 1 mm/min was one window of 1e9 samples.
# The parts join on the path with the same tangent, so nothing stops between them. Every
# program of nc_programs/ has only shorter blocks (plans unchanged).
PART_NOMINAL_S = 10.0
MAX_PART_SWEEP_RAD = math.pi  # an arc part turns at most half a circle (never a whole one)
CHUNK_SAMPLES = 20_000  # a straight move or dwell goes out in chunks of at most this


def contour_parts(block: LineBlock | ArcBlock, max_feed_mm_s: float
                  ) -> list[LineBlock | ArcBlock]:
    """The block itself when short, else equal parts of at most PART_NOMINAL_S each."""
    feed = max(min(block.feed_mm_s, max_feed_mm_s), 1e-9)
    n = math.ceil(block.length_mm / feed / PART_NOMINAL_S)
    if n <= 1:
        return [block]
    if isinstance(block, LineBlock):
        return _line_parts(block, n)
    return _arc_parts(block, max(n, math.ceil(abs(block.sweep_rad) / MAX_PART_SWEEP_RAD)))


def _line_parts(block: LineBlock, n: int) -> list[LineBlock]:
    start, end = np.array(block.start), np.array(block.end)
    points = [tuple(float(c) for c in start + (end - start) * (i / n)) for i in range(n)]
    points.append(block.end)
    return [replace(block, start=points[i], end=points[i + 1])  # type: ignore[arg-type]
            for i in range(n)]


def _arc_parts(block: ArcBlock, n: int) -> list[ArcBlock]:
    cx, cy = block.center
    r = block.radius_mm
    a0 = math.atan2(block.start[1] - cy, block.start[0] - cx)
    sweep = block.sweep_rad
    z = block.start[2]
    points = [(cx + r * math.cos(a0 + sweep * i / n), cy + r * math.sin(a0 + sweep * i / n), z)
              for i in range(n)]
    points[0] = block.start
    points.append(block.end)
    return [replace(block, start=points[i], end=points[i + 1], turns=0) for i in range(n)]


def chunk_bounds(n_samples: int) -> list[tuple[int, int]]:
    """[i0, i1) ranges of at most CHUNK_SAMPLES covering n_samples."""
    return [(i, min(i + CHUNK_SAMPLES, n_samples)) for i in range(0, n_samples, CHUNK_SAMPLES)]
