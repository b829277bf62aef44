"""Length and bounding box of NC blocks (for `cncctl check`): arcs exactly, NURBS by sampling;
and the travel limits, checked on those boxes in machine coordinates."""

from __future__ import annotations

import math

import numpy as np

from controller.blocks import ArcBlock, HelixBlock, LineBlock, NcBlock, NurbsBlock
from controller.config import MachineConfig
from controller.errors import NcError
from controller.geometry.helix import HelixCurve
from controller.interpreter.arcs import arc_box
from controller.offsets import ZERO_MM, OffsetTable, work_origin

Box = tuple[tuple[float, float, float], tuple[float, float, float]]  # (min xyz, max xyz)
SAMPLES_PER_SPAN = 64
_SPAN_BATCH = 2048  # spans evaluated at once: bounds the temporary arrays


def _sample_spans(block: NurbsBlock, spans: np.ndarray, per_span: int) -> np.ndarray:
    """Points at `per_span` parameters in each listed span (homogeneous de Boor, vectorised)."""
    p, t = block.degree, block.knots
    pw = np.column_stack([block.control_points * block.weights[:, None], block.weights])
    frac = np.arange(per_span) / per_span
    k = np.repeat(spans, per_span)
    u = t[k] + np.tile(frac, spans.size) * (t[k + 1] - t[k])
    d = pw[k[:, None] - p + np.arange(p + 1)[None, :]]  # (N, p+1, 3)
    for r in range(1, p + 1):
        for j in range(p, r - 1, -1):
            lo, hi = t[j + k - p], t[j + 1 + k - r]
            alpha = ((u - lo) / (hi - lo))[:, None]
            d[:, j] = (1.0 - alpha) * d[:, j - 1] + alpha * d[:, j]
    c = d[:, p]
    return c[:, :2] / c[:, 2:3]


def nurbs_samples(block: NurbsBlock, per_span: int = SAMPLES_PER_SPAN):
    """Yield (m, 2) arrays of consecutive curve points, batch by batch, ending at the end point."""
    p, t = block.degree, block.knots
    n = block.control_points.shape[0]
    spans = np.nonzero(t[p + 1 : n + 1] > t[p:n])[0] + p  # the non-empty knot spans
    for i in range(0, spans.size, _SPAN_BATCH):
        yield _sample_spans(block, spans[i : i + _SPAN_BATCH], per_span)
    yield block.control_points[-1:].astype(float)


def nurbs_length_and_box(block: NurbsBlock) -> tuple[float, Box]:
    """Polyline length through dense samples (under-estimates by ~1e-7 relative) and sample box."""
    length = 0.0
    last: np.ndarray | None = None
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    for pts in nurbs_samples(block):
        if last is not None:
            pts = np.vstack([last, pts])
        length += float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
        lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
        last = pts[-1:]
    z = block.z_mm
    return length, ((float(lo[0]), float(lo[1]), z), (float(hi[0]), float(hi[1]), z))


def nurbs_hull_box(block: NurbsBlock) -> Box:
    """The box of a NURBS's control points, which holds the curve (its weights are positive:
    the curve lies in the points' convex hull); no sampling."""
    lo, hi = block.control_points.min(axis=0), block.control_points.max(axis=0)
    z = block.z_mm
    return (float(lo[0]), float(lo[1]), z), (float(hi[0]), float(hi[1]), z)


def line_length_and_box(block: LineBlock) -> tuple[float, Box]:
    (sx, sy, sz), (ex, ey, ez) = block.start, block.end
    length = math.dist(block.start, block.end)
    # min(s, e) and max(s, e) as min() and max() give them (s on a tie), without their calls:
    # this runs for every G0/G1 line of a program
    return length, ((ex if ex < sx else sx, ey if ey < sy else sy, ez if ez < sz else sz),
                    (ex if ex > sx else sx, ey if ey > sy else sy, ez if ez > sz else sz))


def arc_sweep_rad(block: ArcBlock) -> float:
    """ArcBlock.sweep_rad with math instead of numpy scalars (this runs once per arc)."""
    (sx, sy, _), (ex, ey, _) = block.start, block.end
    cx, cy = block.center
    a0, a1 = math.atan2(sy - cy, sx - cx), math.atan2(ey - cy, ex - cx)
    sweep = ((a0 - a1) if block.clockwise else (a1 - a0)) % (2 * math.pi)
    sweep = (2 * math.pi if sweep <= 1e-12 else sweep) + 2 * math.pi * block.turns
    return -sweep if block.clockwise else sweep


def arc_length_and_box(block: ArcBlock) -> tuple[float, Box]:
    (sx, sy, z), (ex, ey, _) = block.start, block.end
    cx, cy = block.center
    sweep = arc_sweep_rad(block)
    r = math.hypot(sx - cx, sy - cy)
    if abs(sweep) >= 2 * math.pi:
        r_max = max(r, math.hypot(ex - cx, ey - cy))
        return abs(sweep) * r, ((cx - r_max, cy - r_max, z), (cx + r_max, cy + r_max, z))
    x0, y0, x1, y1 = arc_box(sx, sy, ex, ey, cx, cy, sweep)
    return abs(sweep) * r, ((x0, y0, z), (x1, y1, z))


def helix_length_and_box(block: HelixBlock) -> tuple[float, Box]:
    """Exact length and box of a helix or of a G18/G19 arc."""
    curve = HelixCurve.from_block(block)
    return curve.length_mm, curve.box()


def travel_error(path: str, block: NcBlock, axis: str, reached_mm: float, lo_mm: float,
                 hi_mm: float, offsets: OffsetTable | None = None) -> NcError:
    """The error of a block that leaves an axis's travel. Blocks, and so `reached_mm`, are in
    machine coordinates; with a work offset in force the message also gives the program's
    coordinate there (in mm)."""
    name = axis.upper()
    i = "XYZ".index(name)
    where = f"{reached_mm:.4f} mm in machine coordinates"
    if offsets is not None and work_origin(offsets)[i] != 0.0:
        frame = offsets.active_name + (" + G92" if offsets.g92_mm != ZERO_MM else "")
        where += (f" ({name}{reached_mm - work_origin(offsets)[i]:.4f} mm in the program's "
                  f"{frame} frame)")
    return NcError(path, block.source.first_line, 1, name,
                   f"{name} travel limit exceeded: the path reaches {where}, travel is "
                   f"[{lo_mm:g}, {hi_mm:g}] mm")


class TravelLimits:
    """The machine's soft limits (config `axes.*.travel_mm`), checked on the box of each motion
    block before any motion; the boxes are in machine coordinates, as the blocks are."""

    def __init__(self, config: MachineConfig) -> None:
        self.axes = [(i, name, *config.axis(name).travel_mm)
                     for i, name in enumerate(("x", "y", "z")) if config.has_axis(name)]

    def holds(self, box: Box) -> bool:
        """Whether the box lies inside the travel of every axis."""
        lo, hi = box
        return all(tlo <= lo[i] and hi[i] <= thi for i, _, tlo, thi in self.axes)

    def check(self, path: str, block: NcBlock, box: Box,
              offsets: OffsetTable | None = None) -> None:
        """Raise travel_error at the first axis the box leaves; `offsets` (the table in force
        for the block, e.g. ProgramOffsets.table while reading) only adds to the message."""
        lo, hi = box
        for i, name, tlo, thi in self.axes:
            if lo[i] < tlo:
                raise travel_error(path, block, name, lo[i], tlo, thi, offsets)
            if hi[i] > thi:
                raise travel_error(path, block, name, hi[i], tlo, thi, offsets)
