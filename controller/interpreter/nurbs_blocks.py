"""NURBS blocks from G-code: LinuxCNC G5.2 ... G5.3 and G6.2 with explicit knots (Fanuc form)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from controller.blocks import NurbsBlock, PathControl, Source, polygon_length_mm
from controller.errors import NcError
from controller.geometry.nurbs import Nurbs
from controller.geometry.nurbs_split import kink_knots, split_at, still_spans
from controller.interpreter.codes import WordError

MIN_ORDER, MAX_ORDER = 2, 6
# A NURBS block is planned in one piece (lines and arcs are split: generator/long_blocks.py);
# one whose control polygon (longer than the curve) takes longer than this at its feed is
# refused, so that its samples stay a bounded array (10 minutes: 600,000 at 1 kHz).
MAX_NURBS_NOMINAL_S = 600.0
MAX_SPAN_RATIO = 1e4  # G6.2 knot spans: widest over narrowest (see _check_spacing)
MAX_CONTROL_POINTS = 100_000  # one block is held in memory; bounded so memory stays bounded


def check_order(order: float, word: str) -> int:
    """The order word (L for G5.2, P for G6.2) as an int in 2..6."""
    if order != int(order) or not MIN_ORDER <= order <= MAX_ORDER:
        raise WordError(word, f"NURBS order {word}{order:g} must be an integer from "
                              f"{MIN_ORDER} to {MAX_ORDER}")
    return int(order)


# Weights further apart than this within one block make the curve ill-conditioned: a weight
# of 1e-19 next to 1 asked for arc-length tables of 149 GiB; at a ratio of 1e4 one three-point
# curve already planned 1.8 GB of samples at 0.004 mm/s, another broke Amax twelve-fold, while
# at 1e3 both plan normally. Scaling every weight alike changes nothing, so only the ratio is
# bounded; conic arcs of up to 170 degrees need a ratio under 12.
MAX_WEIGHT_RATIO = 1e3


def _check_weight(weight: float, word: str, lo_hi: tuple[float, float] | None = None) -> float:
    """lo_hi: the block's smallest and largest weight so far (kept as they come: a min and a
    max over the whole list at each point made 20,000 points take 28 s)."""
    if weight <= 0.0:
        raise WordError(word, f"NURBS weight {word}{weight:g} must be positive")
    if lo_hi is not None:
        lo, hi = lo_hi
        if weight > hi * MAX_WEIGHT_RATIO or weight * MAX_WEIGHT_RATIO < lo:
            other = lo if weight > hi else hi
            raise WordError(word, f"NURBS weight {word}{weight:g} and {other:g}, another "
                                  f"weight of the block, are more than a factor "
                                  f"{MAX_WEIGHT_RATIO:g} apart: the curve would be "
                                  "ill-conditioned")
    return weight


def uniform_clamped_knots(n: int, order: int) -> np.ndarray:
    """LinuxCNC's G5.2 knot vector: `order` zeros, 1, 2, ..., then `order` copies of n-order+1."""
    inner = np.arange(1, n - order + 1, dtype=float)
    return np.concatenate([np.zeros(order), inner, np.full(order, float(n - order + 1))])


class NurbsCollector:
    """Gathers the control points (and, for G6.2, the knots) of one NURBS block."""

    def __init__(self, kind: str, order: int, x: float, y: float, weight: float, z_mm: float,
                 feed_mm_s: float, path: PathControl, program: str, line: int,
                 min_gap_mm: float = 0.0) -> None:
        self.min_gap_mm = min_gap_mm  # two control points nearer than this must be the same
        self.kind = kind  # "G5.2", "G6.2" or "G5.1" (splines.py)
        self.order = order
        self.points: list[tuple[float, float]] = [(x, y)]
        self.weights: list[float] = [_check_weight(weight, "R" if kind == "G6.2" else "P")]
        self.weight_range = (weight, weight)
        self.knots: list[float] = []
        self.knot_lines: list[int] = []  # program line of each knot, for error messages
        self.z_mm = z_mm
        self.feed_mm_s = feed_mm_s
        self.path = path
        self.program = program
        self.first_line = line
        self.last_line = line
        self.knot_only = False  # G6.2: knot-only lines have started

    def add_point(self, x: float, y: float, weight: float, line: int) -> None:
        if self.knot_only:
            raise WordError("X", "NURBS control point after the knot-only lines")
        points = self.points
        if len(points) >= MAX_CONTROL_POINTS:
            raise WordError("X", f"NURBS with more than {MAX_CONTROL_POINTS} control points")
        last_x, last_y = points[-1]
        gap_mm = math.hypot(x - last_x, y - last_y)
        if 0.0 < gap_mm < self.min_gap_mm:
            raise WordError("X", f"NURBS control point {gap_mm:.3g} mm from the one before: "
                                 f"nearer than the {self.min_gap_mm:g} mm pulse but not the same "
                                 "point, a hook no machine can follow (repeat the point exactly "
                                 "for a corner, or move it apart)")
        lo, hi = self.weight_range
        if not lo <= weight <= hi:  # (a weight within the block's so far passes the checks)
            _check_weight(weight, "R" if self.kind == "G6.2" else "P", self.weight_range)
            self.weight_range = (min(lo, weight), max(hi, weight))
        self.weights.append(weight)
        points.append((x, y))
        self.last_line = line

    def add_knot(self, knot: float, line: int, knot_only: bool) -> None:
        if self.knots and knot < self.knots[-1]:
            raise WordError("K", f"NURBS knots must not decrease: K{knot:g} after "
                                 f"K{self.knots[-1]:g}")
        if knot_only:
            self.knot_only = True
            if len(self.knots) >= len(self.points) + self.order:
                raise WordError("K", f"too many knots: {len(self.points)} control points of "
                                     f"order {self.order} need {len(self.points) + self.order}")
        self.knots.append(knot)
        self.knot_lines.append(line)
        self.last_line = line

    def _fail(self, line: int, word: str, message: str) -> NcError:
        return NcError(self.program, line, 1, word, message)

    def finish(self, end_line: int | None = None, max_feed_mm_s: float = np.inf) -> NurbsBlock:
        """Check the whole block and build it; errors name the line where the block ends."""
        last = end_line if end_line is not None else self.last_line
        n, order = len(self.points), self.order
        if n < order:
            raise self._fail(last, self.kind, f"NURBS of order {order} needs at least {order} "
                                              f"control points, got {n}")
        points = np.array(self.points, dtype=float)
        polygon_mm = polygon_length_mm(points)
        feed = min(self.feed_mm_s, max_feed_mm_s)
        if polygon_mm > feed * MAX_NURBS_NOMINAL_S:
            raise self._fail(last, self.kind,
                             f"NURBS of {polygon_mm:.0f} mm (control polygon) at "
                             f"{feed * 60:g} mm/min may take over {MAX_NURBS_NOMINAL_S:g} s: a "
                             "NURBS is planned whole; raise the feed or split the curve")
        knots = self._knot_vector(last)
        return NurbsBlock(
            degree=order - 1,
            control_points=points,
            weights=np.array(self.weights, dtype=float),
            knots=knots,
            z_mm=self.z_mm,
            feed_mm_s=self.feed_mm_s,
            path=self.path,
            source=Source(self.program, self.first_line, last),
        )

    def _knot_vector(self, last: int) -> np.ndarray:
        n, order = len(self.points), self.order
        if self.kind != "G6.2":  # G5.2, G5.1
            return uniform_clamped_knots(n, order)
        if len(self.knots) != n + order:
            raise self._fail(last, "K", f"NURBS knot count {len(self.knots)} must equal control "
                                        f"points + order = {n} + {order} = {n + order}")
        k = self.knots
        if k[0] != k[order - 1]:
            raise self._fail(self.knot_lines[order - 1], "K",
                             f"NURBS knots not clamped: the first {order} knots must be equal")
        if k[-order] != k[-1]:
            raise self._fail(last, "K",
                             f"NURBS knots not clamped: the last {order} knots must be equal")
        if not k[order - 1] < k[n]:
            raise self._fail(last, "K", "NURBS knot vector has an empty parameter range")
        self._check_inner_multiplicity(k, n, order)
        self._check_spacing(k, n, order, last)
        return np.array(k, dtype=float)

    def _check_spacing(self, k: list[float], n: int, order: int, last: int) -> None:
        """Knot spans (of the parameter range) more than MAX_SPAN_RATIO apart make the
        parametric speed vary as much: K0 K1 K100000 planned a 15 mm curve to crawl for 506 s,
        and wider ratios asked for 40-100 GiB of samples. G5.2's knots are uniform."""
        spans = np.diff(np.array(k[order - 1:n + 1], dtype=float))
        spans = spans[spans > 0.0]
        if spans.size > 1 and spans.max() > MAX_SPAN_RATIO * spans.min() * (1.0 + 1e-9):
            raise self._fail(last, "K", f"NURBS knot spans range from {spans.min():.6g} to "
                                        f"{spans.max():.6g}, more than a factor "
                                        f"{MAX_SPAN_RATIO:g} apart: a parametrisation this "
                                        "uneven cannot be planned; respace the knots")

    def _check_inner_multiplicity(self, k: list[float], n: int, order: int) -> None:
        """An inner knot repeated `order` times breaks the curve in two: it jumps from one
        control point to the next (the plan then went 317 mm off the path); `order - 1` times
        is a corner, which the planner handles."""
        i = order
        while i < n:
            j = i
            while j + 1 < n and k[j + 1] == k[i]:
                j += 1
            if j - i + 1 >= order:
                raise self._fail(self.knot_lines[j], "K",
                                 f"NURBS knot K{k[i]:g} repeated {j - i + 1} times inside the "
                                 f"curve: at most {order - 1} (the order less one), or the curve "
                                 "breaks apart there")
            i = j + 1


def split_at_corners(block: NurbsBlock) -> list[NurbsBlock]:
    """The block as NURBS blocks that meet where its tangent jumps (a knot of full multiplicity,
    a cusp) and around any stretch where it stands still (repeated control points): each such
    corner then is a joint between blocks, blended within the tolerance under G64 or stopped
    at, as a corner between two G1 lines is; a part of zero length is no motion."""
    if _smooth(block):
        return [block]
    still = still_spans(block.degree, block.knots, block.control_points)
    u0, u1 = float(block.knots[block.degree]), float(block.knots[-block.degree - 1])
    cuts = sorted({*kink_knots(Nurbs.from_block(block)), *(u for span in still for u in span)}
                  - {u0, u1})
    parts: list[NurbsBlock] = []
    knots, points, weights = block.knots, block.control_points, block.weights
    for u in cuts:
        left, (knots, points, weights) = split_at(block.degree, knots, points, weights, u)
        parts.append(replace(block, knots=left[0], control_points=left[1], weights=left[2]))
    if not parts:
        return [block]
    parts.append(replace(block, knots=knots, control_points=points, weights=weights))
    return parts


def _smooth(block: NurbsBlock) -> bool:
    """Neither two neighbouring control points the same nor an inner knot repeated `degree`
    times: then kink_knots and still_spans find nothing (their own first tests), so most
    blocks are not split, without building a curve or a numpy call per test."""
    points = block.control_points.tolist()
    if any(a == b for a, b in zip(points, points[1:], strict=False)):
        return False
    p = block.degree
    knots = block.knots.tolist()
    u_start, u_end = knots[p], knots[-p - 1]
    run, last = 0, None
    for u in knots:  # non-decreasing: equal knots are neighbours
        if u_start < u < u_end:
            run = run + 1 if u == last else 1
            if run >= p:
                return False
        last = u
    return True
