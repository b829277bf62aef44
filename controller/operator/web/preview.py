"""A program's path as the panel draws it: lines, arcs and NURBS sampled into polylines in the
program's own work frame, each piece with its source line, read by the interpreter."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.blocks import ArcBlock, LineBlock, NurbsBlock
from controller.config import MachineConfig
from controller.errors import NcError
from controller.geometry.nurbs import Nurbs
from controller.interpreter.program import read_program

MAX_POINTS = 200_000  # a preview beyond this is cut short (and says so)
CHORD_MM = 0.02  # the sampled curve leaves the true one by at most this (arcs)
MAX_PIECE_POINTS = 2_000  # one arc or NURBS sampled with at most this many points
NURBS_POINTS_PER_SPAN = 16


@dataclass
class Preview:
    """Pieces: {"line": source line, "kind": rapid|feed|arc|nurbs, "points": [[x, y, z]...]}."""

    pieces: list[dict[str, Any]] = field(default_factory=list)
    points: int = 0
    truncated: bool = False
    error: str | None = None
    low_mm: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    high_mm: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def add(self, line: int, kind: str, points: np.ndarray) -> bool:
        """Add one piece; False once the preview is full."""
        if self.points + len(points) > MAX_POINTS:
            self.truncated = True
            return False
        rounded = np.round(points, 4)
        if self.points == 0:
            self.low_mm, self.high_mm = rounded.min(0).tolist(), rounded.max(0).tolist()
        else:
            self.low_mm = np.minimum(self.low_mm, rounded.min(0)).tolist()
            self.high_mm = np.maximum(self.high_mm, rounded.max(0)).tolist()
        self.pieces.append({"line": line, "kind": kind, "points": rounded.tolist()})
        self.points += len(points)
        return True

    def as_dict(self) -> dict[str, Any]:
        return {"pieces": self.pieces, "points": self.points, "truncated": self.truncated,
                "error": self.error, "low_mm": self.low_mm, "high_mm": self.high_mm}


def arc_points(block: ArcBlock) -> np.ndarray:
    """The arc (and its helix in Z, if any) sampled within CHORD_MM of the circle."""
    r_mm = max(block.radius_mm, 1e-9)
    sweep = block.sweep_rad
    step = 2.0 * np.arccos(max(-1.0, 1.0 - CHORD_MM / r_mm))  # chord error = CHORD_MM
    n = int(min(MAX_PIECE_POINTS, max(2, np.ceil(abs(sweep) / max(step, 1e-6)) + 1)))
    a0 = np.arctan2(block.start[1] - block.center[1], block.start[0] - block.center[0])
    angles = a0 + np.linspace(0.0, sweep, n)
    z = np.linspace(block.start[2], block.end[2], n)
    return np.column_stack((block.center[0] + r_mm * np.cos(angles),
                            block.center[1] + r_mm * np.sin(angles), z))


def nurbs_points(block: NurbsBlock) -> np.ndarray:
    """The NURBS evaluated at NURBS_POINTS_PER_SPAN points per knot span."""
    curve = Nurbs.from_block(block)
    knots = np.unique(block.knots)
    spans = max(1, len(knots) - 1)
    n = int(min(MAX_PIECE_POINTS, spans * NURBS_POINTS_PER_SPAN + 1))
    u = np.linspace(curve.u_start, curve.u_end, n)
    xy = curve.evaluate(u, order=0)[0]
    return np.column_stack((xy, np.full(n, block.z_mm)))


def program_preview(path: str, config: MachineConfig,
                    start_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Preview:
    """The program read from its first line, from start_mm, with no work offset in force: the
    coordinates are the program's own (its work frame). A program error ends the preview
    where it is met and is kept in `error` (file, line and word, as `cncctl check` says)."""
    out = Preview()
    try:
        for block in read_program(path, config, start_mm=start_mm):
            if isinstance(block, LineBlock):
                pts = np.array([block.start, block.end], dtype=float)
                kind = "rapid" if block.rapid else "feed"
            elif isinstance(block, ArcBlock):
                pts, kind = arc_points(block), "arc"
            elif isinstance(block, NurbsBlock):
                pts, kind = nurbs_points(block), "nurbs"
            else:
                continue
            if not out.add(block.source.first_line, kind, pts):
                break
    except NcError as exc:
        out.error = str(exc)
    return out
