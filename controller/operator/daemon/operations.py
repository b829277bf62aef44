"""The daemon's operator commands during and between jobs: hold, resume, feed override, jog,
home, and the work offset table (kept in the state directory across restarts)."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

from controller.config import MachineConfig
from controller.motion.types import MotionState
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
from controller.operator.daemon import manual
from controller.operator.daemon.job import Emit, Job
from controller.operator.daemon.log import NOTICE, EventLog
from controller.operator.daemon.protocol import ProtocolError
from controller.operator.daemon.state_dir import StateDir, StateFileError

OFFSETS_FILE = "offsets.json"
SYSTEMS = ("G54", "G55", "G56", "G57", "G58", "G59")


class OperatorCommands:
    """Mixed into Machine: the attributes below are Machine's."""

    config: MachineConfig
    log: EventLog
    state_dir: Path
    state_files: StateDir
    state_problems: list[str]
    job: Job | None
    _lock: threading.RLock
    offsets: OffsetTable

    def _position_mm(self) -> dict[str, float] | None: ...

    def start_job(self, name: str, text: bytes, emit: Emit, manual_move: bool = False,
                  timeout_s: float | None = None, optional_stop: bool = False,
                  from_line: int | None = None) -> int: ...

    def require_idle(self) -> None: ...

    def require_position(self, what: str) -> None: ...

    def _is_running(self) -> bool: ...

    def jog(self, axis: str, distance_mm: float | None, direction: int, feed_mm_min: float,
            emit: Emit, timeout_s: float | None) -> tuple[int, str]:
        """Jog one axis as a one-line job within the soft limits; (job, what it does)."""
        with self._lock:
            self.require_idle()  # a latched e-stop or fault is said before anything else
            self.require_position("jog")
        position = self._position_mm() or {}
        text, note = manual.jog_program(self.config, position, axis, distance_mm, direction,
                                        feed_mm_min)
        job = self.start_job(f"jog {axis.upper()}", text.encode(), emit, manual_move=True,
                             timeout_s=timeout_s)
        self.log.log(NOTICE, note)
        return job, note

    def home(self, axes: list[str]) -> None:
        manual.start_homing(self, axes)

    def resume(self) -> None:
        """Continue a job paused at a program pause (M0), held, or on its way to a hold."""
        with self._lock:
            job = self.job
            waiting = job is not None and job.progress is not None and (
                job.progress.state in (MotionState.PAUSED, MotionState.HELD) or job.holding)
            if job is not None and job.cancel is not None:  # e-stopped or aborted: stopping
                raise ProtocolError("stopping", f"the job is stopping ({job.cancel}): nothing "
                                                "to resume")
            if not waiting or job.runtime is None:
                raise ProtocolError("not-paused", "no job is paused or held")
            job.holding = False
            job.runtime.request_resume()
        self.log.log(NOTICE, f"job {job.number}: resumed at line {job.progress.line}")

    def hold(self) -> None:
        """Feed hold: the running job decelerates along the path and waits for resume."""
        with self._lock:
            job = self.job
            if job is None or job.runtime is None or not self._is_running():
                raise ProtocolError("not-running", "no job is running")
            job.holding = True
            job.runtime.request_hold()
        self.log.log(NOTICE, f"job {job.number}: feed hold at line "
                             f"{job.progress.line if job.progress else 0}")

    def feed(self, percent: float) -> None:
        """Feed override for this and the next jobs (0-150 %; 0 holds until raised)."""
        with self._lock:
            self.feed_override_pct = percent
            job = self.job
            if job is not None and job.runtime is not None:
                job.runtime.set_feed_override(percent)
        self.log.log(NOTICE, f"feed override {percent:g} %")

    feed_override_pct = 100.0

    # -- work offsets -----------------------------------------------------------------------
    def load_offsets(self) -> None:
        """The table kept across restarts. One that cannot be read (a link, a FIFO, not a
        table) is kept aside under a new name and reported: the work offsets are then all
        zero, which status says until they are set again."""
        try:
            raw = self.state_files.read(OFFSETS_FILE)
            self.offsets = OffsetTable() if raw is None else from_json(
                json.loads(raw.decode("utf-8")))
        except (StateFileError, ValueError) as exc:
            kept = self.state_files.keep_aside(OFFSETS_FILE)
            self.offsets = OffsetTable()
            self.state_problems.append(
                f"the work offset table {OFFSETS_FILE} could not be read ({exc}); kept as "
                f"{kept}: the work offsets are all zero until set again")

    def store_offsets(self, table: OffsetTable, why: str) -> None:
        with self._lock:
            try:
                self.state_files.write_atomic(OFFSETS_FILE, (json.dumps(
                    to_json(table), indent=2) + "\n").encode())
            except OSError as exc:
                raise OffsetsError(str(self.state_files.path / OFFSETS_FILE), "cannot write the "
                                   f"offset table: {exc.strerror or exc}") from None
            self.offsets = table
        self.log.log(NOTICE, f"work offsets ({why}): "
                                 f"{describe_text(table, self.config.axis_names)}")

    def offset(self, action: str, system: str | None, values: dict[str, float],
               here: bool) -> dict[str, Any]:
        """set SYSTEM (X.. Y.. origins in machine coordinates, or --here: the current position
        becomes the system's zero for the axes given, all of them if none), select SYSTEM,
        clear-g92; only between jobs (a running program reads the table it started with)."""
        with self._lock:
            self.require_idle()
            table = self.offsets
            if action == "clear-g92":
                table = with_g92(table, (0.0, 0.0, 0.0))
            else:
                n = _system_number(system)
                if action == "select":
                    table = select(table, n)
                else:
                    table = with_system(table, n, self._origin(table, n, values, here))
            self.store_offsets(table, f"{action} {system or ''}".strip())
            return describe(table)

    def _origin(self, table: OffsetTable, n: int, values: dict[str, float],
                here: bool) -> tuple[float, float, float]:
        origin = list(table.systems_mm[n - 1])
        if here:
            pos = self._position_mm() or {}
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

    def offsets_status(self) -> dict[str, Any]:
        out: dict[str, Any] = {"offsets": describe(self.offsets)}
        pos = self._position_mm()
        if pos is not None:
            machine = [pos.get(a, 0.0) for a in "xyz"]
            work = to_program_mm(self.offsets, machine)
            out["work_position_mm"] = {a: round(float(work["xyz".index(a)]), 6) for a in pos}
        return out


def _system_number(system: str | None) -> int:
    if system is None or system.upper() not in SYSTEMS:
        raise ProtocolError("bad-field", f"system must be one of {', '.join(SYSTEMS)}")
    return SYSTEMS.index(system.upper()) + 1
