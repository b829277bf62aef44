"""The daemon's work offset table, kept in the state directory across restarts: read at
start-up, changed by `cncctl offset` between jobs, left by a program that ends."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from typing import Any

from controller.config import MachineConfig
from controller.offsets import (
    OffsetsError,
    OffsetTable,
    describe,
    describe_text,
    from_json,
    select,
    to_json,
    to_program_mm,
    with_g92,
    with_system,
)
from controller.operator.daemon.log import NOTICE, EventLog
from controller.operator.daemon.protocol import ProtocolError
from controller.operator.daemon.state_dir import StateDir, StateFileError

OFFSETS_FILE = "offsets.json"
SYSTEMS = ("G54", "G55", "G56", "G57", "G58", "G59")


class OffsetStore:
    """The table in force and its file; written under the machine's lock (a job's end and
    `cncctl offset` both store it)."""

    def __init__(self, config: MachineConfig, state_files: StateDir, log: EventLog,
                 lock: threading.RLock,
                 position_mm: Callable[[], dict[str, float] | None]) -> None:
        self.config, self.state_files, self.log, self._lock = config, state_files, log, lock
        self.position_mm = position_mm  # where the machine stands, None if unknown
        self.table = OffsetTable()

    def load(self) -> str | None:
        """The table kept across restarts; the problem, if any. One that cannot be read (a
        link, a FIFO, not a table) is kept aside under a new name and reported: the work
        offsets are then all zero, which status says until they are set again."""
        try:
            raw = self.state_files.read(OFFSETS_FILE)
            self.table = OffsetTable() if raw is None else from_json(
                json.loads(raw.decode("utf-8")))
        except (StateFileError, ValueError) as exc:
            kept = self.state_files.keep_aside(OFFSETS_FILE)
            self.table = OffsetTable()
            return (f"the work offset table {OFFSETS_FILE} could not be read ({exc}); kept as "
                    f"{kept}: the work offsets are all zero until set again")
        return None

    def store(self, table: OffsetTable, why: str) -> None:
        with self._lock:
            try:
                self.state_files.write_atomic(OFFSETS_FILE, (json.dumps(
                    to_json(table), indent=2) + "\n").encode())
            except OSError as exc:
                raise OffsetsError(str(self.state_files.path / OFFSETS_FILE), "cannot write the "
                                   f"offset table: {exc.strerror or exc}") from None
            self.table = table
        self.log.log(NOTICE, f"work offsets ({why}): "
                             f"{describe_text(table, self.config.axis_names)}")

    def change(self, action: str, system: str | None, values: dict[str, float],
               here: bool) -> dict[str, Any]:
        """set SYSTEM (X.. Y.. origins in machine coordinates, or here: the current position
        becomes the system's zero for the axes given, all of them if none), select SYSTEM,
        clear-g92 (the caller holds the lock and has checked that no job runs)."""
        table = self.table
        if action == "clear-g92":
            table = with_g92(table, (0.0, 0.0, 0.0))
        else:
            n = _system_number(system)
            if action == "select":
                table = select(table, n)
            else:
                table = with_system(table, n, self._origin(table, n, values, here))
        self.store(table, f"{action} {system or ''}".strip())
        return describe(table)

    def _origin(self, table: OffsetTable, n: int, values: dict[str, float],
                here: bool) -> tuple[float, float, float]:
        origin = list(table.systems_mm[n - 1])
        if here:
            pos = self.position_mm() or {}
            axes = values or {a: 0.0 for a in pos}
            for axis, reads in axes.items():
                if axis not in pos:
                    raise ProtocolError("bad-field", f"no axis {axis.upper()}")
                # the current position reads `reads` in that system (G10 L20), G92 included
                origin["xyz".index(axis)] = pos[axis] - reads - table.g92_mm["xyz".index(axis)]
        else:
            if not values:
                raise ProtocolError("bad-field", "set needs values (X10 Y-5) or here")
            for axis, value in values.items():
                if axis not in self.config.axis_names:
                    raise ProtocolError("bad-field", f"no axis {axis.upper()}")
                origin["xyz".index(axis)] = value
        return origin[0], origin[1], origin[2]

    def status(self) -> dict[str, Any]:
        out: dict[str, Any] = {"offsets": describe(self.table)}
        pos = self.position_mm()
        if pos is not None:
            machine = [pos.get(a, 0.0) for a in "xyz"]
            work = to_program_mm(self.table, machine)
            out["work_position_mm"] = {a: round(float(work["xyz".index(a)]), 6) for a in pos}
        return out


def _system_number(system: str | None) -> int:
    if system is None or system.upper() not in SYSTEMS:
        raise ProtocolError("bad-field", f"system must be one of {', '.join(SYSTEMS)}")
    return SYSTEMS.index(system.upper()) + 1
