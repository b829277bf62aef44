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
        # np.linalg.norm's own operations (its wrapper costs 4 us, the interpreter asks every
        # G1 line): the BLAS dot rounds with FMA, so math.hypot would differ in the last bit.
        d = np.subtract(self.end, self.start)
        return float(np.sqrt(d.dot(d)))


SPIRAL_MIN_MM = 1e-9  # an arc's end radius this close to its start radius: a circle


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
    def radius_change_mm(self) -> float:
        """End radius minus start radius (LinuxCNC accepts up to 0.028 mm and moves on a
        spiral); 0 below SPIRAL_MIN_MM, which is rounding."""
        end = float(np.hypot(self.end[0] - self.center[0], self.end[1] - self.center[1]))
        change = end - self.radius_mm
        return change if abs(change) > SPIRAL_MIN_MM else 0.0

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


# The machine axes (x 0, y 1, z 2) of each arc plane: its first and second axis, then its
# normal, as LinuxCNC orders them (G18's plane is Z then X, so that its normal is +Y).
PLANE_AXES: dict[str, tuple[int, int, int]] = {"G17": (0, 1, 2), "G18": (2, 0, 1),
                                                "G19": (1, 2, 0)}


@dataclass(frozen=True, slots=True)
class HelixBlock:
    """G2/G3 that moves a third axis: a G17 arc with a Z end (a helix), or any G18 (ZX) or G19
    (YZ) arc, with or without motion along the plane's normal (absolute mm).

    `center` is the axis point in the plane's two coordinates (first, second axis of
    PLANE_AXES); the sweep is counter-clockwise positive seen from the normal's + side."""

    plane: str  # "G17", "G18" or "G19"
    start: Point3
    end: Point3
    center: tuple[float, float]
    clockwise: bool
    turns: int  # extra full turns (G2 P>1)
    feed_mm_s: float
    path: PathControl
    source: Source

    def in_plane(self, point: Point3) -> tuple[float, float, float]:
        """A machine point as (first, second, normal) coordinates of the plane."""
        a, b, n = PLANE_AXES[self.plane]
        return point[a], point[b], point[n]

    @property
    def radius_mm(self) -> float:
        s1, s2, _ = self.in_plane(self.start)
        return float(np.hypot(s1 - self.center[0], s2 - self.center[1]))

    @property
    def sweep_rad(self) -> float:
        """Signed swept angle in the plane: positive counter-clockwise."""
        (s1, s2, _), (e1, e2, _) = self.in_plane(self.start), self.in_plane(self.end)
        c1, c2 = self.center
        return _signed_sweep(float(np.arctan2(s2 - c2, s1 - c1)),
                             float(np.arctan2(e2 - c2, e1 - c1)), self.clockwise, self.turns)

    @property
    def radius_change_mm(self) -> float:
        """End radius minus start radius in the plane (a spiral, as ArcBlock's); 0 below
        SPIRAL_MIN_MM."""
        e1, e2, _ = self.in_plane(self.end)
        end = float(np.hypot(e1 - self.center[0], e2 - self.center[1]))
        change = end - self.radius_mm
        return change if abs(change) > SPIRAL_MIN_MM else 0.0

    @property
    def axial_mm(self) -> float:
        """Displacement along the plane's normal (the helix's rise)."""
        return self.in_plane(self.end)[2] - self.in_plane(self.start)[2]

    @property
    def length_mm(self) -> float:
        """The helix unrolled is a straight line of legs r * sweep and the rise (exact on a
        circle; of the mean radius on a spiral)."""
        mean_mm = self.radius_mm + 0.5 * self.radius_change_mm
        return float(np.hypot(mean_mm * self.sweep_rad, self.axial_mm))


def _signed_sweep(a0: float, a1: float, clockwise: bool, turns: int) -> float:
    """From angle a0 to a1 the given way round, a full circle when they meet, plus turns."""
    sweep = ((a0 - a1) if clockwise else (a1 - a0)) % (2 * np.pi)
    sweep = (2 * np.pi if sweep <= 1e-12 else sweep) + 2 * np.pi * turns
    return -float(sweep) if clockwise else float(sweep)


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


PROBE_CODES = ("G38.2", "G38.3", "G38.4", "G38.5")


@dataclass(frozen=True, slots=True)
class ProbeBlock:
    """G38.2-G38.5 (LinuxCNC): a straight move from start toward end at the feed that ends
    where the probe trips (G38.2/3: contact made; G38.4/5: contact lost), so nothing after it
    can be planned before its result: planning stops here and goes on from where the machine
    stopped. G38.2 and G38.4 are an error if the move ends without tripping."""

    code: str  # one of PROBE_CODES
    start: Point3
    end: Point3
    feed_mm_s: float
    source: Source

    @property
    def toward(self) -> bool:
        """True: the probe moves toward the work (trips on contact); False: away from it."""
        return self.code in ("G38.2", "G38.3")

    @property
    def error_on_miss(self) -> bool:
        return self.code in ("G38.2", "G38.4")

    def as_line(self) -> LineBlock:
        """The whole move, as planned from rest to rest (the probe may end it sooner)."""
        return LineBlock(self.start, self.end, self.feed_mm_s, False,
                         PathControl(PathMode.EXACT_STOP), self.source)


@dataclass(frozen=True, slots=True)
class OutputChange:
    """One machine output set to a value: "spindle" ("off", "cw", "ccw"), "spindle_rpm",
    "coolant_mist", "coolant_flood" (bool), "digital_<P>" (bool), "analog_<E>" (float)."""

    name: str
    value: str | bool | float


@dataclass(frozen=True, slots=True)
class OutputBlock:
    """The outputs one line changes (M3-M5 S, M7-M9, M64, M65, M68), set with the machine
    at rest at `position`; then wait_s (a spindle's spin-up) before the next move. synced
    (M62, M63, M67): set at the first sample of the next move instead, without a stop."""

    changes: tuple[OutputChange, ...]
    position: Point3
    wait_s: float
    source: Source
    synced: bool = False


MotionBlock = LineBlock | ArcBlock | NurbsBlock
NcBlock = (LineBlock | ArcBlock | HelixBlock | NurbsBlock | DwellBlock | StopBlock | AuxBlock
           | ProbeBlock | OutputBlock)
