"""How the daemon runs a job: check the program, the approach of a run from a line, the run,
and its result into the journal, the log and the job's connection (a mixin of Machine)."""

from __future__ import annotations

import os
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

from controller.errors import NcError
from controller.motion.types import MotionProgress, MotionResult, Outcome
from controller.operator.daemon.check_process import CheckCancelled, check_in_child
from controller.operator.daemon.job import Job, State, progress_event
from controller.operator.daemon.log import ERR, INFO, NOTICE
from controller.operator.run.from_line import approach_program
from controller.operator.run.view import result_summary
from controller.runtime.processes import Runtime, RuntimeOptions


class JobRunner:
    """The job thread's work; Machine provides the state, the lock, the drive and the rest."""

    state_dir: Path
    config: Any
    journal: Any
    log: Any
    offsets: Any
    feed_override_pct: float
    last_job: dict[str, Any]
    runtime_options: Any

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
        offsets = None if job.manual_move else self.offsets
        try:
            checked = check_in_child(path, self.config, offsets, start_mm, job.from_line,
                                     lambda: job.cancel is not None, self._beat)
            job.approach_mm = checked.approach_mm
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
            job.runtime = Runtime(path, self.config, replace(
                self._options(job), offsets=offsets, from_line=job.from_line,
                override_off_lines=checked.override_off_lines))
            job.runtime.set_feed_override(self.feed_override_pct)
            self.journal.start(job.name, job.sha256, job.lines)
            self._beat()
            self._set_state(State.RUNNING)
        job.emit({"event": "start", "program": job.name, "config": self.config.name,
                  "drive": self.config.drive.backend, "job": job.number})
        result = job.runtime.run()
        if result.outcome is Outcome.DONE and not job.manual_move:
            self.store_offsets(checked.table, f"left by {job.name}")
        self._record(job, result)

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
            self.publish("progress", event)
        return replace(base, drive=self.drive, keep_drive_open=True, on_progress=progress,
                       start_mm=job.start_mm, optional_stop=job.optional_stop)

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
                                position_mm=position, fault=result.message or None)
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
