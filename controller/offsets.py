"""Work offsets: the G54-G59 coordinate systems, the G92 offset, and the file that keeps them.

Program coordinates = machine coordinates - (origin of the active system + G92 offset), all in
mm (LinuxCNC's model without rotation, G52 and G59.1-G59.3). The table is immutable; the
interpreter makes a new one at each G10, G92 or G54-G59 and reports it through ProgramOffsets.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from controller.errors import OffsetsError
from controller.probe import ProbeResults
from controller.table_file import read_capped, write_atomic

Point3 = tuple[float, float, float]
SYSTEM_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59")  # system n is SYSTEM_NAMES[n - 1]
SYSTEMS = len(SYSTEM_NAMES)
ZERO_MM: Point3 = (0.0, 0.0, 0.0)
FILE_FORMAT = "phcnc-offsets"
FILE_VERSION = 1
MAX_FILE_BYTES = 1 << 16  # a table is a few hundred bytes; anything larger is not one
_KEYS = {"format", "version", "active", "systems_mm", "g92_mm"}


def _point(values: Sequence[float], what: str) -> Point3:
    """Three finite floats, or ValueError naming `what`."""
    if isinstance(values, (str, bytes)) or len(values) != 3:
        raise ValueError(f"{what} must be three numbers (x, y, z)")
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
            raise ValueError(f"{what} must be three numbers (x, y, z), got {v!r}")
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"{what} must be finite, got {v!r}")
        out.append(f)
    return out[0], out[1], out[2]


def _system_number(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= SYSTEMS:
        raise ValueError(f"coordinate system must be 1..{SYSTEMS} (G54..G59), got {n!r}")
    return int(n)


@dataclass(frozen=True, slots=True)
class OffsetTable:
    """The six work coordinate systems (origins in machine mm), the G92 offset (mm) and the
    active system (1..6 for G54..G59)."""

    systems_mm: tuple[Point3, ...] = (ZERO_MM,) * SYSTEMS
    g92_mm: Point3 = ZERO_MM
    active: int = 1

    def __post_init__(self) -> None:
        if len(self.systems_mm) != SYSTEMS:
            raise ValueError(f"an offset table has {SYSTEMS} coordinate systems (G54..G59), "
                             f"got {len(self.systems_mm)}")
        systems = tuple(_point(p, SYSTEM_NAMES[i]) for i, p in enumerate(self.systems_mm))
        object.__setattr__(self, "systems_mm", systems)
        object.__setattr__(self, "g92_mm", _point(self.g92_mm, "G92 offset"))
        object.__setattr__(self, "active", _system_number(self.active))

    @property
    def active_name(self) -> str:
        """G54 .. G59."""
        return SYSTEM_NAMES[self.active - 1]

    def origin_mm(self, n: int) -> Point3:
        """Origin of system n (1..6) in machine mm."""
        return self.systems_mm[_system_number(n) - 1]


def work_origin(table: OffsetTable) -> Point3:
    """Active origin + G92 offset as floats: machine = program + this."""
    ox, oy, oz = table.systems_mm[table.active - 1]
    gx, gy, gz = table.g92_mm
    return ox + gx, oy + gy, oz + gz


def work_origin_mm(table: OffsetTable) -> np.ndarray:
    """Active origin + G92 offset, shape (3,): machine = program + this."""
    return np.array(work_origin(table), dtype=float)


def with_system(table: OffsetTable, n: int, origin: Sequence[float]) -> OffsetTable:
    """The table with system n's (1..6) origin set to `origin` (machine mm)."""
    n = _system_number(n)
    systems = list(table.systems_mm)
    systems[n - 1] = _point(origin, SYSTEM_NAMES[n - 1])
    return replace(table, systems_mm=tuple(systems))


def with_g92(table: OffsetTable, offset: Sequence[float]) -> OffsetTable:
    """The table with the G92 offset set to `offset` (mm); ZERO_MM clears it."""
    return replace(table, g92_mm=_point(offset, "G92 offset"))


def select(table: OffsetTable, n: int) -> OffsetTable:
    """The table with system n (1..6, G54..G59) active."""
    return replace(table, active=_system_number(n))


def to_machine_mm(table: OffsetTable, program_mm: Sequence[float]) -> np.ndarray:
    """Machine coordinates of a point given in the active program frame (mm)."""
    return np.asarray(program_mm, dtype=float) + work_origin_mm(table)


def to_program_mm(table: OffsetTable, machine_mm: Sequence[float]) -> np.ndarray:
    """Coordinates in the active program frame (mm) of a point given in machine coordinates."""
    return np.asarray(machine_mm, dtype=float) - work_origin_mm(table)


def _xyz(p: Point3) -> dict[str, float]:
    return {"x": p[0], "y": p[1], "z": p[2]}


def describe(table: OffsetTable) -> dict[str, Any]:
    """JSON-able summary (for `cncctl status`): active system, every origin, G92, the sum."""
    return {
        "active": table.active_name,
        "systems_mm": {name: _xyz(p) for name, p in zip(SYSTEM_NAMES, table.systems_mm,
                                                         strict=True)},
        "g92_mm": _xyz(table.g92_mm),
        "work_origin_mm": _xyz(work_origin(table)),
    }


def describe_text(table: OffsetTable, axes: Sequence[str]) -> str:
    """One line for the event log: the active system, the origin in force, every system set
    and G92 if set, on the machine's axes (mm)."""
    def words(p: Sequence[float]) -> str:
        return " ".join(f"{a.upper()}{p['xyz'.index(a)]:.3f}" for a in axes)

    def nonzero(p: Sequence[float]) -> bool:
        return any(p["xyz".index(a)] != 0.0 for a in axes)

    text = f"{table.active_name} active, work origin {words(work_origin(table))}"
    set_ = [f"{name} {words(p)}" for name, p in zip(SYSTEM_NAMES, table.systems_mm, strict=True)
            if nonzero(p)]
    if set_:
        text += "; " + ", ".join(set_)
    if nonzero(table.g92_mm):
        text += f"; G92 {words(table.g92_mm)}"
    return text


def to_json(table: OffsetTable) -> dict[str, Any]:
    """The file's form of a table (what save_offsets writes)."""
    return {
        "format": FILE_FORMAT,
        "version": FILE_VERSION,
        "active": table.active_name,
        "systems_mm": {name: list(p) for name, p in zip(SYSTEM_NAMES, table.systems_mm,
                                                         strict=True)},
        "g92_mm": list(table.g92_mm),
    }


def from_json(data: Any) -> OffsetTable:
    """A table from the file's form, read strictly; ValueError says what is wrong."""
    if not isinstance(data, dict):
        raise ValueError("the file must hold one JSON object")
    unknown = data.keys() - _KEYS
    missing = _KEYS - data.keys()
    if unknown:
        raise ValueError(f"unknown key {sorted(unknown)[0]!r}")
    if missing:
        raise ValueError(f"missing key {sorted(missing)[0]!r}")
    if data["format"] != FILE_FORMAT:
        raise ValueError(f"format must be {FILE_FORMAT!r}, got {data['format']!r}")
    if data["version"] != FILE_VERSION or isinstance(data["version"], bool):
        raise ValueError(f"version must be {FILE_VERSION}, got {data['version']!r}")
    if data["active"] not in SYSTEM_NAMES:
        raise ValueError(f"active must be one of {', '.join(SYSTEM_NAMES)}, "
                         f"got {data['active']!r}")
    systems = data["systems_mm"]
    if not isinstance(systems, dict) or set(systems) != set(SYSTEM_NAMES):
        raise ValueError(f"systems_mm must map each of {', '.join(SYSTEM_NAMES)} to [x, y, z]")
    if not isinstance(data["g92_mm"], list):
        raise ValueError("g92_mm must be [x, y, z]")
    points = []
    for name in SYSTEM_NAMES:
        if not isinstance(systems[name], list):
            raise ValueError(f"systems_mm.{name} must be [x, y, z]")
        points.append(_point(systems[name], f"systems_mm.{name}"))
    return OffsetTable(tuple(points), _point(data["g92_mm"], "g92_mm"),
                       SYSTEM_NAMES.index(data["active"]) + 1)


def load_offsets(path: str | os.PathLike[str], missing_ok: bool = True) -> OffsetTable:
    """The table kept in `path`; the default (all zero, G54) when the file does not exist and
    missing_ok (the daemon's own state: none kept yet). A file that cannot be read or is not a
    valid table raises OffsetsError naming it, and so does a missing one a user named
    (`--offsets`: all-zero offsets in its place would move the work elsewhere)."""
    name = os.fspath(path)
    raw = read_capped(name, MAX_FILE_BYTES, ("offset table", "an offset table"), OffsetsError,
                      missing_ok)
    if raw is None:
        return OffsetTable()
    try:
        return from_json(json.loads(raw.decode("utf-8")))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise OffsetsError(name, f"corrupt offset table: {exc}") from exc
    except ValueError as exc:
        raise OffsetsError(name, f"invalid offset table: {exc}") from exc


def save_offsets(path: str | os.PathLike[str], table: OffsetTable) -> None:
    """Write the table atomically: a temporary file in the same folder, fsync, os.replace, then
    fsync of the folder; a crash leaves the old table or the new one, never half of one."""
    name = os.fspath(path)
    try:
        mode = os.stat(name).st_mode & 0o777
    except FileNotFoundError:
        mode = 0o644
    except OSError as exc:
        raise OffsetsError(name, f"cannot write the offset table: {exc.strerror or exc}") from exc
    write_atomic(name, json.dumps(to_json(table), indent=2) + "\n", ".offsets-", "offset table",
                 OffsetsError, mode)


@dataclass
class ProgramOffsets:
    """What the interpreter reports as it reads: `table` is the offset table in force after the
    last line read (pass one to read_program as `track`; after the whole program it is the
    table the program leaves behind)."""

    table: OffsetTable = field(default_factory=OffsetTable)
    # M49 ... M48: [first line, last line] stretches where the feed override is off
    override_off_lines: list[list[int]] = field(default_factory=list)
    # tool changes (controller/io_events.py dicts, t_s None): the run times them as it goes
    io_events: list[dict[str, Any]] = field(default_factory=list)
    # probes: the results known (a run) and the parameters they set (controller/probe.py)
    probes: ProbeResults = field(default_factory=ProbeResults)
    # "LINE: what was accepted that LinuxCNC refuses, and the rule followed" (at most a few)
    warnings: list[str] = field(default_factory=list)
