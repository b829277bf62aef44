"""The daemon's machine: ESTOP -> IDLE -> CHECKING -> RUNNING -> IDLE, and FAULT; one job at a
time, run on the drive the daemon holds open; e-stop and faults latch until reset.

Kept whole: Machine is one state machine under one lock: the operator's commands, the job
thread (check, approach, run, record) and the status all read and change the same state; its
work offset table is a part of its own (OffsetStore), homing goes through manual.py,
`identify` through identify_run.py."""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from controller.config import MachineConfig
from controller.errors import CncError, NcError
from controller.motion.loop import LIMIT_INPUT
from controller.motion.realtime import realtime_threads
from controller.motion.types import MotionProgress, MotionResult, MotionState, Outcome
from controller.operator.check_cmd import refuse_probes
from controller.operator.daemon import identify_run, manual
from controller.operator.daemon.check_process import CheckCancelled, check_in_child
from controller.operator.daemon.job import Emit, Job, State, progress_event
from controller.operator.daemon.journal import IDENTIFY_KEY, Journal
from controller.operator.daemon.log import ERR, INFO, NOTICE, WARNING, EventLog
from controller.operator.daemon.offset_store import OffsetStore
from controller.operator.daemon.protocol import ProtocolError
from controller.operator.daemon.state_dir import StateDir
from controller.operator.daemon.tool_store import ToolStore
from controller.operator.run.from_line import approach_program
from controller.operator.run.io_announce import tool_change_at, tool_prompt
from controller.operator.run.view import result_summary
from controller.runtime.probe_run import ProbeRun
from controller.runtime.processes import Runtime, RuntimeOptions
from drivers.base import CardStatus, Drive
from drivers.errors import LostCommunicationError

JOURNAL_EVERY_S = 0.5  # the journal's last line is at most this old after a crash
MOTION_STALL_S = 1.0  # no motion-loop cycle for this long while running: unhealthy
CHECK_STALL_S = 2.0  # no checked block for this long while checking: unhealthy
ESTOP_INPUT_POLL_S = 0.02  # the drive's e-stop input is read this often (a job's loop: each T)
ESTOP_INPUT = "e-stop input on the drive tripped"


LEFTOVER_PREFIXES = ("job-", "approach-", ".journal.json.", ".offsets.json.", ".tool.tbl.")


class Machine:
    """All state changes go through here, under one lock; jobs run in a thread of their own."""

    def __init__(self, config: MachineConfig, drive: Drive, state_dir: Path, log: EventLog,
                 publish: Callable[[str, dict[str, Any]], None],
                 runtime_options: Callable[[], RuntimeOptions] | None = None) -> None:
        self.config, self.drive, self.log, self.publish = config, drive, log, publish
        self.state_dir = state_dir
        self.runtime_options = runtime_options or RuntimeOptions
        self._lock = threading.RLock()
        self.state = State.ESTOP  # after any (re)start: never moves by itself
        self.fault: str | None = "e-stop latched at start-up: reset to enable"
        self.job: Job | None = None
        self._jobs = 0
        self.beat_s = time.monotonic()  # last sign of life of the check or the motion loop
        self.state_files = StateDir(state_dir)  # checked: owned by us, written by no one else
        self.state_problems: list[str] = []  # state files kept aside at start-up, reported
        self.journal = Journal(self.state_files)
        self.feed_override_pct = 100.0  # of this and the next jobs
        self.last_probe: dict[str, Any] | None = None  # the last G38's result (status)
        self.work_offsets = OffsetStore(config, self.state_files, log, self._lock,
                                        self._position_mm)
        self.tools = ToolStore(config, self.state_files, log, self._lock)
        self.state_problems += [p for p in (self.work_offsets.load(), self.tools.load()) if p]
        self.last_job = self.journal.after_restart()
        identify = self.last_job.pop(IDENTIFY_KEY, None)
        self.last_identify = identify if isinstance(identify, dict) else None
        # The program copies a crashed daemon left (up to 64 MiB each): links not followed.
        self.state_files.remove_leftovers(LEFTOVER_PREFIXES)
        self.state_problems += [p for p in (self.journal.problem,) if p]
        for problem in self.state_problems:
            log.log(ERR, f"state directory: {problem}")
        threading.Thread(target=self._journal_loop, name="journal", daemon=True).start()
        self._disable_drive()  # ESTOP at start-up: the drives are off until reset
        threading.Thread(target=self._estop_input_loop, name="estop-input", daemon=True).start()
        if self.last_job.get("state") == "INTERRUPTED":
            log.log(WARNING, f"the last job {self.last_job.get('program')!r} was interrupted "
                             f"at line {self.last_job.get('last_line')}; it will not resume")

    # -- commands ---------------------------------------------------------------------------
    def start_job(self, name: str, text: bytes, emit: Emit, manual_move: bool = False,
                  timeout_s: float | None = None, optional_stop: bool = False,
                  from_line: int | None = None) -> int:
        """A program (or, manual_move, a jog: allowed before homing, in machine coordinates)
        as the next job; from_line: approach the program's position at that line, go on."""
        with self._lock:
            self.require_idle()
            if not manual_move:
                self.require_homed()
            self._jobs += 1
            job = Job(self._jobs, name, hashlib.sha256(text).hexdigest(), text,
                      text.count(b"\n"), emit, optional_stop=optional_stop,
                      from_line=from_line, manual_move=manual_move)
            self.job = self._last_job_started = job
            self._set_state(State.CHECKING)
        threading.Thread(target=self._run_job, args=(job,), name=f"job-{job.number}",
                         daemon=True).start()
        if timeout_s is not None:
            timer = threading.Timer(timeout_s, self._time_out, args=(job,))
            timer.daemon = True
            timer.start()
        return job.number

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

    def identify(self, fields: dict[str, Any], request_id: Any, emit: Emit) -> None:
        """`identify`: answered on emit once the excitations are designed (or refused)."""
        identify_run.serve(self, fields, request_id, emit)

    identify_run: identify_run.IdentifyRun | None = None  # claimed, or exciting and fitting
    last_identify: dict[str, Any] | None = None  # how the last one ended (`status`)
    _identify_started: identify_run.IdentifyRun | None = None

    def start_identifying(self, run: identify_run.IdentifyRun) -> None:
        """Under the lock: the claimed identify starts moving (an e-stop meanwhile stops)."""
        if self.identify_run is not run or self.state is not State.IDLE:
            raise ProtocolError("estop" if self.state is State.ESTOP else "busy",
                                f"the machine went {self.state.value} meanwhile: nothing "
                                "moved")
        run.moving = True
        self._identify_started = run
        self._beat()
        self._set_state(State.IDENTIFYING)
        self.journal.identify({"event": "started", "axes": [p.name for p in run.plans]})

    def end_identify(self, run: identify_run.IdentifyRun, fault: str | None,
                     outcome: dict[str, Any]) -> None:
        """The identify is over: FAULT latches, an e-stop latched meanwhile stays (the drives
        disabled), else IDLE; its outcome kept for `status` (the config text aside)."""
        with self._lock:
            if self.identify_run is run:
                self.identify_run = None
            self.last_identify = {k: v for k, v in outcome.items() if k != "config_yaml"}
            self.journal.identify(self.last_identify)
            if fault is not None:
                self.fault = fault
                self._set_state(State.FAULT)
            elif self.state is not State.ESTOP:
                self._set_state(State.IDLE)
            if self.state is State.ESTOP:
                self._disable_drive()
        self.log.log(ERR if fault else NOTICE, f"identify {outcome.get('event')}"
                     + (f": {outcome['message']}" if outcome.get("message") else ""))

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

    def offset(self, action: str, system: str | None, values: dict[str, float],
               here: bool) -> dict[str, Any]:
        """`cncctl offset` (see OffsetStore.change), only between jobs: a running program
        reads the table it started with."""
        with self._lock:
            self.require_idle()
            return self.work_offsets.change(action, system, values, here)

    def tool(self, fields: dict[str, Any]) -> dict[str, Any]:
        """`cncctl tool` (see ToolStore.change): a change only between jobs (e-stop or fault
        latched is fine: nothing moves)."""
        with self._lock:
            if fields["action"] != "list" and self.job is not None:
                raise ProtocolError("busy", "a job is running: change tools between jobs")
            return self.tools.change(fields)

    def _time_out(self, job: Job) -> None:
        with self._lock:
            if self.job is job:
                self._stop_job(job, "jog time-out: stopped along the path")

    def _is_running(self) -> bool:
        return self.state is State.RUNNING

    @property
    def lock(self) -> threading.RLock:
        return self._lock

    def set_state_homing(self) -> None:
        self._set_state(State.HOMING)

    def end_homing(self, failure: str | None) -> None:
        """Homing is over: IDLE; a drive that halted during it latches FAULT."""
        with self._lock:
            halted = False
            try:
                halted = self.drive.status().halted
            except CncError:
                halted = True
            if halted:
                self.fault = failure or "drive halted during homing"
                self._set_state(State.FAULT)
            elif self.state is not State.ESTOP:
                self._set_state(State.IDLE)
            if self.state is State.ESTOP:
                self._disable_drive()  # the homing aborted by an e-stop: now the drives off
                failure = failure or self.last_homing  # the e-stop's word, said at once
            self.last_homing = failure or "done"

    last_homing: str | None = None

    def require_homed(self) -> None:
        if self.config.allow_unhomed:
            return
        missing = manual.unhomed_axes(self.config, self.drive.homed())
        if missing:
            raise ProtocolError("not-homed", f"not homed: {', '.join(missing)} (`cncctl "
                                             "home`; the config's allow_unhomed permits runs "
                                             "without)")

    def require_position(self, what: str) -> None:
        """Refuse a jog or a homing while the drive cannot say where the machine is."""
        try:
            self.drive.position_counts()
        except CncError as exc:
            raise ProtocolError("position-unknown", f"cannot {what}: the position is unknown "
                                f"({exc}): `cncctl reset` opens the drive again, then "
                                "`cncctl home`") from None

    def position_text(self) -> str:
        pos = self._position_mm() or {}
        return " ".join(f"{k.upper()}{v:.3f}" for k, v in pos.items())

    def abort(self, reason: str) -> str:
        """Stop the job along the path; the state it leads to (IDLE, or the latched ESTOP;
        the reply said RUNNING while a held job stopped)."""
        with self._lock:
            job = self.job
            if self.identify_run is not None and job is None:
                self.identify_run.request_stop(reason)
                return self.state.value if self.state is State.ESTOP else State.IDLE.value
            if job is None:
                raise ProtocolError("not-running", "no job is running")
            self._stop_job(job, reason)
            return self.state.value if self.state is State.ESTOP else State.IDLE.value

    def estop(self, reason: str) -> None:
        """Category 1: a running job stops at Amax along the path, then the drives are
        disabled (at once when nothing moves); latched until reset, which enables them."""
        with self._lock:
            self.fault = reason
            homing = self.state is State.HOMING
            if homing:
                self.drive.abort_homing(reason)
                # Said at once: `cncctl home` printed "None" while the homing thread ended.
                self.last_homing = f"aborted by the e-stop ({reason})"
            self._set_state(State.ESTOP)
            run = self.identify_run
            if run is not None:
                run.request_stop(reason)  # along its path; the loop then disables the drives
            if self.job is not None:
                self._stop_job(self.job, reason, estop=True)
            elif not homing and (run is None or not run.moving):
                self._disable_drive()
        self.log.log(ERR, f"e-stop: {reason}")

    def _disable_drive(self) -> None:
        """The drives off (idempotent); a drive that cannot be told is logged, not raised:
        the e-stop is latched whatever the drive answers."""
        try:
            if not self.drive.disabled:
                self.drive.disable()
        except CncError as exc:
            self.log.log(ERR, f"e-stop: the drives could not be disabled: {exc}")

    def _estop_input_loop(self) -> None:
        """The drive's e-stop input, between jobs too (a job's motion loop reads it each
        cycle and stops at once): tripped, it e-stops as `cncctl estop` does. A limit switch
        that opens while idle latches FAULT naming it (jobs and jogs: their motion loop's)."""
        limit: str | None = None  # the switch open at the last look
        while True:
            time.sleep(ESTOP_INPUT_POLL_S)
            try:
                tripped = self.drive.estop_input()
                limit, was = self.drive.limit_input(), limit
            except CncError:
                continue
            if tripped and self.state is not State.ESTOP:
                self.estop(ESTOP_INPUT)
            elif limit is not None and limit != was:  # opened (one it stands on is known)
                self._limit_at_rest(limit)

    def _limit_at_rest(self, limit: str) -> None:  # not while homing: it uses the switches
        with self._lock:
            if self.state is State.IDLE and self.job is None and self.identify_run is None:
                self.fault = f"{LIMIT_INPUT.format(limit)} (machine at rest)"
                self._set_state(State.FAULT)
                self.log.log(ERR, f"fault: {self.fault}")

    def reset(self) -> None:
        with self._lock:
            if self.state is State.HOMING:
                raise ProtocolError("busy", "homing: wait for it, or e-stop")
            if self._estop_input_open():
                raise ProtocolError("estop", "the e-stop input on the drive is open "
                                             "(tripped): close it, then reset")
            if self.job is not None or self.identify_run is not None:
                raise ProtocolError("busy", f"a job is {self.state.value.lower()}: abort it "
                                            "first")
            try:
                self._reset_drive()
            except CncError as exc:
                raise ProtocolError("drive", f"drive reset failed: {exc}") from None
            self.fault = None
            self._set_state(State.IDLE)
        self.log.log(NOTICE, "reset: idle")

    def _reset_drive(self) -> None:
        """Clear the drive's latched condition; after a lost link, open it afresh (bring-up,
        position read again, axes to be homed again): the old handle is dead, and a reset over
        it failed until the daemon was restarted."""
        if not self.drive.is_open:  # an earlier reopen failed: try again, or say why not
            self.log.log(NOTICE, "reset: the drive is not open: opening it")
            self.drive.open()
            return
        try:
            status = self.drive.status()
        except LostCommunicationError:
            status = CardStatus.LOST_COMM
        if CardStatus.LOST_COMM in status:
            self.log.log(NOTICE, "reset: the drive link was lost: opening it again")
            self.drive.close()
            with realtime_threads():  # its threads as at start-up (see main.Daemon)
                self.drive.open()
        elif status.halted or self.drive.disabled:
            self.drive.reset()  # after an e-stop: the drives enabled again

    def _estop_input_open(self) -> bool:
        try:
            return self.drive.estop_input()
        except CncError:
            return False

    def terminate(self, reason: str) -> None:
        """SIGTERM: stop a running job along the path (the caller waits for wait_idle)."""
        with self._lock:
            if self.state is State.HOMING:
                self.drive.abort_homing(reason)
            if self.identify_run is not None:
                self.identify_run.request_stop(reason)
            if self.job is not None:
                self._stop_job(self.job, reason)

    def wait_idle(self, timeout_s: float) -> bool:
        """True once the last job started has ended and sent its last event."""
        # The last identify started, too: it leaves identify_run before its last event is
        # posted, and a daemon stopping must deliver that event.
        for run in (self.identify_run, self._identify_started):
            if run is not None and not run.done.wait(timeout_s):
                return False
        job = self._last_job_started
        return job is None or job.done.wait(timeout_s)

    _last_job_started: Job | None = None
    scheduling: dict[str, Any] | None = None  # probed at start-up, then the last job's

    # -- the job thread: check, approach, run, record ------------------------------------------
    def _run_job(self, job: Job) -> None:
        workdir = tempfile.mkdtemp(prefix="job-", dir=self.state_dir)
        path = os.path.join(workdir, "program.nc")
        try:
            with open(path, "wb") as fh:
                fh.write(job.text)
            job.text = b""
            self._check_and_run(job, path)
        except Exception as exc:  # noqa: BLE001 - a job must never take the daemon down
            self._finish(job, State.FAULT, f"job failed: {type(exc).__name__}: {exc}")
            job.emit({"event": "fault", "message": f"job failed: {exc}"})
        finally:
            for p in (path, workdir):
                try:
                    os.unlink(p) if p == path else os.rmdir(p)
                except OSError:
                    pass
            job.done.set()

    def _check_and_run(self, job: Job, path: str) -> None:
        self.log.log(INFO, f"job {job.number}: checking {job.name!r} ({job.sha256[:12]})")
        start_mm = self._start_mm()
        offsets = None if job.manual_move else self.work_offsets.table
        config = self.tools.job_config(self.config)  # the tool table in force for this job
        try:
            checked = check_in_child(path, config, offsets, start_mm, job.from_line,
                                     lambda: job.cancel is not None, self._beat)
            job.approach_mm = checked.approach_mm
            if checked.probe_lines and self.drive.probe_input() is None:
                refuse_probes(path, checked.probe_lines, f"the {self.config.drive.backend} "
                              "drive has no probe input")
        except CheckCancelled:
            with self._lock:
                self._cancelled(job)
            return
        except NcError as exc:
            message = NcError(job.name, exc.line, exc.col, exc.word, exc.message).format()
            self.log.log(NOTICE, f"job {job.number} rejected: {message}")
            self._finish(job, None, None)  # IDLE before the client hears: it may run again
            job.emit({"event": "rejected", "message": message})
            return
        if job.approach_mm is not None and not self._approach(job, start_mm):
            return
        with self._lock:
            if self._cancelled(job):
                return
            job.start_mm = start_mm
            job.tool_changes = checked.io_events
            options = replace(self._options(job), offsets=offsets, from_line=job.from_line,
                              override_off_lines=checked.override_off_lines)
            # G38: a stretch per probe on the daemon's drive (runtime/probe_run.py)
            job.runtime = ProbeRun(path, config, options, self.drive, checked.probe_lines,
                                   lambda e: self._probed(job, e)) if checked.probe_lines \
                else Runtime(path, config, options)
            job.runtime.set_feed_override(self.feed_override_pct)
            self.journal.start(job.name, job.sha256, job.lines)
            self._beat()
            self._set_state(State.RUNNING)
        job.emit({"event": "start", "program": job.name, "config": self.config.name,
                  "drive": self.config.drive.backend, "job": job.number})
        result = job.runtime.run()
        if result.outcome is Outcome.DONE and not job.manual_move:
            self.work_offsets.store(checked.table, f"left by {job.name}")
        self._record(job, result)

    def _probed(self, job: Job, event: dict[str, Any]) -> None:
        """A probe's result: on the job's connection and in `status` (`last_probe`)."""
        self.last_probe = event
        job.emit(event)

    def _approach(self, job: Job, start_mm: tuple[float, float, float]) -> bool:
        """Run from line: the straight move (Z up first, then XY, then Z down, on a mill) to
        where the program stands at that line; False if it did not end there."""
        text = approach_program(self.config, start_mm, job.approach_mm or start_mm)
        if not text:
            return True
        fd, approach = tempfile.mkstemp(prefix="approach-", suffix=".nc", dir=self.state_dir)
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        try:
            with self._lock:
                if self._cancelled(job):  # no approach either
                    return False
                job.start_mm = start_mm
                job.runtime = Runtime(approach, self.config, self._options(job))
                # The journal names the program and the line to run from again, not the
                # approach's own lines (nor the job before, as it did).
                job.approaching = True
                self.journal.start(job.name, job.sha256, job.lines)
                self.journal.update(last_line=job.from_line)
                self._set_state(State.RUNNING)
            self.log.log(NOTICE, f"job {job.number}: approach to line {job.from_line}")
            result = job.runtime.run()
        finally:
            os.unlink(approach)
        with self._lock:  # the journal loop must not write the approach's lines after this
            job.progress = None
            job.approaching = False
            if result.outcome is not Outcome.DONE:
                self._record(job, result, line=job.from_line)
        return result.outcome is Outcome.DONE

    def _cancelled(self, job: Job) -> bool:
        """A job aborted (or e-stopped) while checking ends here, nothing moved (under the
        lock, before its runtime would start)."""
        if job.cancel is None:
            return False
        self._finish(job, None, None)  # IDLE (or ESTOP) before the client hears
        job.emit({"event": "aborted", "message": job.cancel})
        return True

    def _options(self, job: Job) -> RuntimeOptions:
        base = self.runtime_options()

        def progress(p: MotionProgress) -> None:
            self._beat()
            job.progress = p
            if base.on_progress is not None:
                base.on_progress(p)
            event = progress_event(p)
            job.emit(event)
            for io in tool_change_at(job.tool_changes, p, job.emitted_lines):
                job.emit(io)
            self.publish("progress", event)
        return replace(base, drive=self.drive, keep_drive_open=True, on_progress=progress,
                       start_mm=job.start_mm, optional_stop=job.optional_stop,
                       on_event=job.emit)  # output changes: to `cncctl run --json`

    def _record(self, job: Job, result: MotionResult, line: int | None = None) -> None:
        """The job's result into the journal, the log and its connection; line: the program
        line to record instead of the result's (an approach's lines are not the program's)."""
        summary = result_summary(result)
        sched = result.extra.get("scheduling")
        if sched is not None:
            self.scheduling = sched  # what the job's processes got (`cncctl status`)
            if not sched["privileged"]:
                self.log.warn_once("rt", f"scheduling: {sched['summary']}")
        position = summary["final_position_mm"] if result.position_known else None
        with self._lock:  # not interleaved with the journal loop's last-line writes
            self.journal.update(state=result.outcome.value.upper(),
                                last_line=result.line if line is None else line,
                                position_mm=position, fault=result.message or None,
                                model_residual_um=result.model_residual_um,
                                model_warning=result.model_warning)
            self.last_job = dict(self.journal.entry)
        if result.outcome is Outcome.FAULT:
            self.log.log(ERR, f"job {job.number} fault at line {result.line}: "
                              f"{result.message}")
            self._finish(job, State.FAULT, result.message)
        else:
            self.log.log(INFO, f"job {job.number} {result.outcome.value} at line "
                               f"{result.line}{': ' + result.message if result.message else ''}")
            self._finish(job, None, None)
        job.emit(summary)

    # -- status and health --------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        with self._lock:
            job, p = self.job, (self.job.progress if self.job else None)
            state, out_tool = self.state.value, None
            if p is not None and p.state is MotionState.PAUSED and self.state is State.RUNNING:
                state = "PAUSED"  # at a program pause (M0): `cncctl resume` continues
                out_tool = tool_prompt(job.tool_changes, p.line)  # type: ignore[union-attr]
            if p is not None and p.state is MotionState.HELD and self.state is State.RUNNING:
                state = "HELD"  # feed hold (or 0 % override): `cncctl resume` continues
            out: dict[str, Any] = {"state": state, "fault": self.fault,
                                   "tool_change": out_tool,
                                   "program": job.name if job else None,
                                   "job": job.number if job else None,
                                   "program_sha256": job.sha256 if job else None,
                                   "manual_move": job.manual_move if job else None}
            # On the approach of a run from line N: N, not the approach's own lines.
            approaching = job is not None and job.approaching
        # The last job's line is in last_job.
        out["line"] = (job.from_line if approaching else p.line) if p else None
        out["feed_mm_s"] = round(p.feed_mm_s, 3) if p else 0.0
        out["ferror_um"] = round(p.ferror_um, 1) if p else 0.0
        out["feed_override_pct"] = self.feed_override_pct
        out["position_mm"] = self._position_mm()
        out["drives"] = "disabled" if self.drive.disabled else "enabled"
        out["estop_input"] = self._estop_input_open()
        out["outputs"] = self.drive.outputs()  # spindle, coolant, digital, analog
        out["homed"] = manual.homed_status(self)
        out.update(self.work_offsets.status())
        out["last_homing"] = self.last_homing
        out["last_job"] = self.last_job
        out["last_identify"] = self.last_identify
        out["last_probe"] = self.last_probe  # G38: line, code, tripped, trip_mm, stop_mm
        out["state_problems"] = list(self.state_problems)
        out["scheduling"] = self.scheduling
        return out

    def healthy(self) -> str | None:
        with self._lock:
            state = self.state
        quiet_s = time.monotonic() - self.beat_s
        if state is State.RUNNING and quiet_s > MOTION_STALL_S:
            return f"motion loop silent for {quiet_s:.1f} s"
        if state is State.IDENTIFYING and quiet_s > MOTION_STALL_S:
            return f"identify loop silent for {quiet_s:.1f} s"
        if state is State.CHECKING and quiet_s > CHECK_STALL_S:
            return f"program check silent for {quiet_s:.1f} s"
        return None

    def _start_mm(self) -> tuple[float, float, float]:
        """Where the machine stands (its step counters): the next program starts there."""
        return self.drive.commanded_xyz_mm()

    def _position_mm(self) -> dict[str, float] | None:
        try:
            _, enc = self.drive.position_counts()
        except CncError:
            return None
        return {a.name: round(float(c) * a.pulse_mm, 6)
                for a, c in zip(self.config.axes, enc, strict=True)}

    # -- internals ----------------------------------------------------------------------------
    def require_idle(self) -> None:
        """Raise the reason a job cannot start now (busy, e-stop, fault), if there is one."""
        if self.job is not None:
            raise ProtocolError("busy", f"a job is {self.state.value.lower()} "
                                        "(one job at a time; nothing was queued)")
        if self.state is State.HOMING:
            raise ProtocolError("busy", "homing")
        if self.identify_run is not None:
            raise ProtocolError("busy", "identifying (`cncctl abort` stops it)")
        if self.state is State.ESTOP:
            raise ProtocolError("estop", f"e-stop is latched ({self.fault}): reset first")
        if self.state is State.FAULT:
            raise ProtocolError("fault", f"fault latched ({self.fault}): reset first")

    def _stop_job(self, job: Job, reason: str, estop: bool = False) -> None:
        """Abort (along the path), or e-stop (at Amax, then the drives disabled by the
        motion loop; a job not moving yet never moves, and _finish disables)."""
        job.cancel = job.cancel or reason
        if job.runtime is None:
            return
        controller = job.runtime.controller
        if estop and controller is not None:
            controller.request_estop(reason)
        else:
            job.runtime.request_abort(reason)

    def _set_state(self, state: State) -> None:
        self.state = state
        self.publish("state", {"event": "state", "state": state.value, "fault": self.fault})

    def _finish(self, job: Job, state: State | None, fault: str | None) -> None:
        """The job is over: FAULT latches, an e-stop latched meanwhile stays, else IDLE."""
        with self._lock:
            if self.job is job:
                self.job = None
            if state is State.FAULT:
                self.fault = fault
                self._set_state(State.FAULT)
            elif self.state is not State.ESTOP:
                self._set_state(State.IDLE)
            if self.state is State.ESTOP:
                self._disable_drive()  # an e-stop that came while the job checked or ran

    def _journal_loop(self) -> None:
        """Off the motion thread (a journal write syncs to disk): the line reached, as soon as
        a job has one and then at most every JOURNAL_EVERY_S while it changes."""
        written: tuple[int, int] | None = None  # (job, line) last written
        last_s = 0.0
        while True:
            time.sleep(0.05)
            with self._lock:  # a job's end (_record) writes the journal under it too
                job = self.job
                p = job.progress if job is not None else None
                if p is None or self.state is not State.RUNNING or p.line <= 0 \
                        or job.approaching:
                    continue
                now_s = time.monotonic()
                first = written is None or written[0] != job.number
                if (job.number, p.line) != written and \
                        (first or now_s - last_s >= JOURNAL_EVERY_S):
                    self.journal.update(last_line=p.line)
                    written, last_s = (job.number, p.line), now_s

    def _beat(self, *_: object) -> None:
        self.beat_s = time.monotonic()

    def beat(self) -> None:
        """A sign of life of the identify loop (the watchdog's, as the motion loop's)."""
        self._beat()
