"""Long blocks in bounded parts: a line or arc of hours, a long dwell, planned a piece at a time."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from controller.blocks import ArcBlock, LineBlock, NurbsBlock
from controller.geometry.nurbs import Nurbs
from controller.geometry.nurbs_split import split_at
from controller.numeric import sorted_unique

# A contour line or arc whose nominal time (length over programmed feed) exceeds this is
# planned as parts of at most this: a look-ahead window holds whole blocks, and one arc of a
# million turns (LinuxCNC's G2 P) or a 100 mm line at 1 mm/min was one window of 1e9 samples.
# The parts join on the path with the same tangent, so nothing stops between them. Every
# program of nc_programs/ has only shorter blocks (plans unchanged).
PART_NOMINAL_S = 10.0
MAX_PART_SWEEP_RAD = math.pi  # an arc part turns at most half a circle (never a whole one)
CHUNK_SAMPLES = 20_000  # a straight move or dwell goes out in chunks of at most this
# A NURBS taking longer than this at its feed (by its control polygon, at most 600 s: the
# interpreter refuses longer) is planned as parts split at knots where it is smooth: one at
# F6.2 was one window of 598 s of samples (260 MB). Every NURBS of nc_programs/ and of the
# benchmarks is far shorter (plans unchanged).
NURBS_PART_NOMINAL_S = 60.0
SMOOTH_KNOT_SHARE = 0.5  # a knot is cut only where the curvature is under this share of kappa_th


def contour_parts(block: LineBlock | ArcBlock, max_feed_mm_s: float
                  ) -> Iterator[LineBlock | ArcBlock]:
    """The block itself when short, else equal parts of at most PART_NOMINAL_S each, made as
    they are taken (a list of the two million half turns of `G2 P1000000` filled memory)."""
    feed = max(min(block.feed_mm_s, max_feed_mm_s), 1e-9)
    if isinstance(block, LineBlock) and _manhattan_mm(block) < 0.5 * PART_NOMINAL_S * feed:
        # Far inside the limit by a bound of its length, so its exact length (a numpy norm,
        # costly on every line of a G1 program) is not needed.
        return iter([block])
    n = math.ceil(block.length_mm / feed / PART_NOMINAL_S)
    if n <= 1:
        return iter([block])
    if isinstance(block, LineBlock):
        return _line_parts(block, n)
    return _arc_parts(block, max(n, math.ceil(abs(block.sweep_rad) / MAX_PART_SWEEP_RAD)))


def _manhattan_mm(block: LineBlock) -> float:
    """|dx| + |dy| + |dz|: at least the line's length."""
    (x0, y0, z0), (x1, y1, z1) = block.start, block.end
    return abs(x1 - x0) + abs(y1 - y0) + abs(z1 - z0)


def _line_parts(block: LineBlock, n: int) -> Iterator[LineBlock]:
    start, end = np.array(block.start), np.array(block.end)
    before = block.start
    for i in range(1, n + 1):
        after = block.end if i == n else tuple(float(c) for c in start + (end - start) * (i / n))
        yield replace(block, start=before, end=after)  # type: ignore[arg-type]
        before = after


def _arc_parts(block: ArcBlock, n: int) -> Iterator[ArcBlock]:
    cx, cy = block.center
    r = block.radius_mm
    a0 = math.atan2(block.start[1] - cy, block.start[0] - cx)
    sweep = block.sweep_rad
    change = block.radius_change_mm  # a spiral: see ArcCurve
    z = block.start[2]
    before = block.start
    for i in range(1, n + 1):
        ri = r + change * i / n
        after = block.end if i == n else (cx + ri * math.cos(a0 + sweep * i / n),
                                          cy + ri * math.sin(a0 + sweep * i / n), z)
        yield replace(block, start=before, end=after, turns=0)
        before = after


def nurbs_parts(block: NurbsBlock, max_feed_mm_s: float,
                kappa_th_per_mm: float) -> list[NurbsBlock]:
    """The block itself when its control polygon takes at most NURBS_PART_NOMINAL_S at its
    feed, else parts of about that split at knots where the curve is smooth (curvature, from
    both sides, under SMOOTH_KNOT_SHARE of kappa_th: never inside a corner zone). The parts
    join with the same tangent and curvature as the curve had, so nothing stops between them."""
    feed = max(min(block.feed_mm_s, max_feed_mm_s), 1e-9)
    if block.polygon_length_mm / feed <= NURBS_PART_NOMINAL_S:
        return [block]
    curve = Nurbs.from_block(block)
    knots = sorted_unique(block.knots[(block.knots > curve.u_start) & (block.knots < curve.u_end)])
    if not knots.size:
        return [block]
    kappa = np.maximum(curve.curvature(knots), curve.curvature(np.nextafter(knots, -np.inf)))
    smooth = knots[kappa < SMOOTH_KNOT_SHARE * kappa_th_per_mm]
    cuts = _cuts(curve.s_of_u(smooth) - curve.s_of_u(np.array([curve.u_start]))[0], smooth,
                 NURBS_PART_NOMINAL_S * feed)
    parts: list[NurbsBlock] = []
    k, pts, w = block.knots, block.control_points, block.weights
    for u in cuts:
        left, (k, pts, w) = split_at(block.degree, k, pts, w, u)
        parts.append(replace(block, knots=left[0], control_points=left[1], weights=left[2]))
    parts.append(replace(block, knots=k, control_points=pts, weights=w))
    return parts


def _cuts(s_mm: np.ndarray, u: np.ndarray, budget_mm: float) -> list[float]:
    """Knots (u, at arc lengths s_mm) to cut at: each the last within budget_mm of the cut
    before, or the first beyond it where none is within."""
    cuts: list[float] = []
    last_mm = 0.0
    i = 0
    while i < len(u):
        j = int(np.searchsorted(s_mm, last_mm + budget_mm, side="right")) - 1
        j = max(j, i)
        if j >= len(u) - 1 and s_mm[-1] - last_mm <= budget_mm:
            break  # the rest fits in one part
        cuts.append(float(u[j]))
        last_mm, i = float(s_mm[j]), j + 1
    return cuts


def chunk_bounds(n_samples: int) -> Iterator[tuple[int, int]]:
    """[i0, i1) ranges of at most CHUNK_SAMPLES covering n_samples, made as they are taken."""
    return ((i, min(i + CHUNK_SAMPLES, n_samples)) for i in range(0, n_samples, CHUNK_SAMPLES))
