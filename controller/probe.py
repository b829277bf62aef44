"""Probing (G38.2-G38.5): a probe's result, LinuxCNC's parameters #5061-#5063 and #5070, and
the simulated work the sim card and the serial peer probe against (with the exact trip point
of a straight move, the reference the tests hold a run to).

A probe move ends early, where the probe trips, so what follows depends on its result: the
interpreter reads on past a probe only once its result is known (`ProbeResults`, in the
order the probes ran: a probe line in a loop runs more than once); `check` reads on as if the
probe went the whole way (the farthest it can go).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

Point3 = tuple[float, float, float]

# LinuxCNC: #5061-#5069 the probed point in the work coordinates in force at the probe (X Y Z
# here), #5070 1 if the probe tripped, 0 if not (G38.3 and G38.5 go on without contact).
PARAM_X, PARAM_Y, PARAM_Z, PARAM_OK = 5061, 5062, 5063, 5070


@dataclass(frozen=True, slots=True)
class ProbeResult:
    """What one probe move found, machine mm: where the probe tripped (the move's end when it
    did not) and where the machine came to rest (past the trip point by the stop at Amax)."""

    line: int
    tripped: bool
    trip_mm: Point3
    stop_mm: Point3

    def parameters(self, origin_mm: Sequence[float]) -> dict[int, float]:
        """#5061-#5063 (the trip point in the program's frame: machine - origin, where the
        origin is the work offset plus the tool length in force) and #5070."""
        x, y, z = (self.trip_mm[i] - origin_mm[i] for i in range(3))
        return {PARAM_X: x, PARAM_Y: y, PARAM_Z: z, PARAM_OK: 1.0 if self.tripped else 0.0}

    def describe(self) -> dict[str, Any]:
        return {"line": self.line, "tripped": self.tripped,
                "trip_mm": [round(v, 6) for v in self.trip_mm],
                "stop_mm": [round(v, 6) for v in self.stop_mm]}


@dataclass
class ProbeResults:
    """The probes' results known so far, in the order the probes ran, and the parameters a
    later evaluator reads.

    barrier: a probe whose result is not known yet ends the interpreter's stream (a run: the
    rest is read again once it is); without it (`check`) a probe is taken to go the whole way.
    resume_after: the stream yields only what follows the probe run that many-th (the one the
    machine has just run), from where it stopped; 0: from the start.
    """

    by_index: list[ProbeResult] = field(default_factory=list)
    barrier: bool = False
    parameters: dict[int, float] = field(default_factory=dict)  # #5061-#5063, #5070 last set
    stopped_at: int | None = None  # the line of the probe the stream ended at (barrier)
    seen: dict[int, str] = field(default_factory=dict)  # every probe read: line -> G38.x
    resume_after: int = 0
    ran: int = 0  # probes read so far in this stream

    def next_result(self) -> tuple[ProbeResult | None, bool]:
        """The result of the probe read now (None: not run yet), and whether the stream
        yields from after it (it is the resume_after-th)."""
        index, self.ran = self.ran, self.ran + 1
        known = self.by_index[index] if index < len(self.by_index) else None
        return known, self.ran == self.resume_after


@dataclass(frozen=True, slots=True)
class Workpiece:
    """The sim card's simulated workpiece: a box, machine mm. The probe is in contact while
    its tip is inside it (touching its faces included)."""

    min_mm: Point3
    max_mm: Point3

    def contact(self, p_mm: Sequence[float]) -> bool:
        return all(self.min_mm[i] <= p_mm[i] <= self.max_mm[i] for i in range(len(p_mm)))


def trip_point(work: Workpiece, start: Sequence[float], end: Sequence[float],
               toward: bool) -> Point3 | None:
    """Where a straight move first trips the probe: contact made (toward) or lost (away);
    None if it never does. Exact (the segment clipped against the box, Liang-Barsky)."""
    d = [end[i] - start[i] for i in range(3)]
    t0, t1 = 0.0, 1.0
    for i in range(3):
        if abs(d[i]) < 1e-15:
            if not work.min_mm[i] <= start[i] <= work.max_mm[i]:
                return None if toward else _at(start, d, 0.0)
            continue
        a = (work.min_mm[i] - start[i]) / d[i]
        b = (work.max_mm[i] - start[i]) / d[i]
        t0, t1 = max(t0, min(a, b)), min(t1, max(a, b))
    if t0 > t1:  # the segment misses the box
        return None if toward else _at(start, d, 0.0)
    if toward:
        return _at(start, d, t0)
    # away: contact is lost where the segment leaves the box (if it started inside)
    return None if t1 >= 1.0 or t0 > 0.0 else _at(start, d, t1)


def _at(start: Sequence[float], d: Sequence[float], t: float) -> Point3:
    return (start[0] + t * d[0], start[1] + t * d[1], start[2] + t * d[2])
