"""Typed NC blocks: what the interpreter yields and the generator consumes (mm, mm/s, s)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

Point3 = tuple[float, float, float]


class PathMode(StrEnum):
    """G61 exact stop, G61.1 exact path, G64 blending (with optional P tolerance)."""

    EXACT_STOP = "G61"
    EXACT_PATH = "G61.1"
    BLEND = "G64"


@dataclass(frozen=True, slots=True)
class PathControl:
    """Modal path control: how the joint to the next block may deviate from the program."""

    mode: PathMode = PathMode.BLEND
    tolerance_mm: float | None = None  # G64 P; None = "as fast as possible" in LinuxCNC terms
    naive_cam_tolerance_mm: float | None = None  # G64 Q


@dataclass(frozen=True, slots=True)
class Source:
    """Where a block comes from: the program file and its first and last line (1-based)."""

    path: str
    first_line: int
    last_line: int


@dataclass(frozen=True, slots=True)
class LineBlock:
    """Straight move G0/G1 from start to end (absolute mm)."""

    start: Point3
    end: Point3
    feed_mm_s: float  # for rapids: the machine's rapid feed
    rapid: bool
    path: PathControl
    source: Source

    @property
    def length_mm(self) -> float:
        return float(np.linalg.norm(np.subtract(self.end, self.start)))


@dataclass(frozen=True, slots=True)
class ArcBlock:
    """Circular move G2/G3 in the XY plane at constant Z (absolute mm)."""

    start: Point3
    end: Point3
    center: tuple[float, float]
    clockwise: bool
    turns: int  # extra full turns (LinuxCNC G2 P>1); 0 for an ordinary arc
    feed_mm_s: float
    path: PathControl
    source: Source

    @property
    def radius_mm(self) -> float:
        return float(np.hypot(self.start[0] - self.center[0], self.start[1] - self.center[1]))

    @property
    def sweep_rad(self) -> float:
        """Signed swept angle: positive counter-clockwise; a full circle when start == end."""
        a0 = np.arctan2(self.start[1] - self.center[1], self.start[0] - self.center[0])
        a1 = np.arctan2(self.end[1] - self.center[1], self.end[0] - self.center[0])
        if self.clockwise:
            sweep = (a0 - a1) % (2 * np.pi)
            sweep = 2 * np.pi if sweep <= 1e-12 else sweep
            return -float(sweep + 2 * np.pi * self.turns)
        sweep = (a1 - a0) % (2 * np.pi)
        sweep = 2 * np.pi if sweep <= 1e-12 else sweep
        return float(sweep + 2 * np.pi * self.turns)

    @property
    def length_mm(self) -> float:
        return abs(self.sweep_rad) * self.radius_mm


def polygon_length_mm(points: np.ndarray) -> float:
    """Length of the polyline through points (n, 2)."""
    return float(np.sum(np.hypot(*np.diff(points, axis=0).T)))


@dataclass(frozen=True, eq=False)
class NurbsBlock:
    """A planar NURBS (G5.2 or G6.2) at constant Z: clamped knots, positive weights."""

    degree: int
    control_points: np.ndarray  # (n, 2) mm
    weights: np.ndarray  # (n,)
    knots: np.ndarray  # (n + degree + 1,), clamped, non-decreasing
    z_mm: float
    feed_mm_s: float
    path: PathControl
    source: Source

    @property
    def start(self) -> Point3:
        p = self.control_points[0]
        return (float(p[0]), float(p[1]), self.z_mm)

    @property
    def polygon_length_mm(self) -> float:
        """Length of the control polygon: the curve, lying in its hull, is no longer."""
        return polygon_length_mm(self.control_points)

    @property
    def end(self) -> Point3:
        p = self.control_points[-1]
        return (float(p[0]), float(p[1]), self.z_mm)


@dataclass(frozen=True, slots=True)
class DwellBlock:
    """G4 P: wait in place."""

    seconds: float
    position: Point3
    source: Source


class StopKind(StrEnum):
    PAUSE = "M0"
    OPTIONAL_PAUSE = "M1"
    END = "M2"
    END_REWIND = "M30"


@dataclass(frozen=True, slots=True)
class StopBlock:
    """Program stop (M0/M1) or program end (M2/M30): motion comes to rest here."""

    kind: StopKind
    position: Point3
    source: Source


@dataclass(frozen=True, slots=True)
class AuxBlock:
    """Spindle, coolant and tool events (M3 M4 M5 M6 M7 M8 M9 with S and T)."""

    code: str  # "M3", "M5", "M6", ...
    spindle_rpm: float | None = None
    tool: int | None = None
    source: Source = field(default_factory=lambda: Source("", 0, 0))


@dataclass(frozen=True, slots=True)
class OutputChange:
    """One machine output set to a value: "spindle" ("off", "cw", "ccw"), "spindle_rpm",
    "coolant_mist", "coolant_flood" (bool), "digital_<P>" (bool), "analog_<E>" (float)."""

    name: str
    value: str | bool | float


@dataclass(frozen=True, slots=True)
class OutputBlock:
    """The outputs one line changes (M3-M5 S, M7-M9, M62-M65, M67, M68), set with the machine
    at rest at `position`; then wait_s (a spindle's spin-up) before the next move."""

    changes: tuple[OutputChange, ...]
    position: Point3
    wait_s: float
    source: Source


MotionBlock = LineBlock | ArcBlock | NurbsBlock
NcBlock = LineBlock | ArcBlock | NurbsBlock | DwellBlock | StopBlock | AuxBlock | OutputBlock
