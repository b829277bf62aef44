"""The three-process runtime: interpreter -> NC FIFO -> generator -> shm ring -> motion -> drive."""

from __future__ import annotations

import functools
import gc
import multiprocessing as mp
import os
import queue
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from controller.config import MachineConfig
from controller.errors import DriveError
from controller.interpreter.fifo import FAILED_MESSAGE
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer, WallPacer
from controller.motion.realtime import MOTION_PRIORITY, Scheduling, back_to_normal, try_realtime
from controller.motion.ring import FLAG_ABORT, FLAG_FAILED, FLAG_FINAL, RefRing
from controller.motion.source import SourceState
from controller.motion.types import MotionProgress, MotionResult, MotionSettings, MotionState
from controller.offsets import OffsetTable, work_origin
from controller.runtime.gc_policy import collect_less
from controller.runtime.stages import (
    BlocksFn,
    GenerateFn,
    blocks_source,
    generator_main,
    interpreter_main,
    preload_stages,
    reference_source,
)
from controller.servo.prediction import axis_servos
from drivers.base import Drive
from drivers.errors import DriveUnavailableError
from drivers.registry import make_drive

# fork: children start in ~ms (time to first motion); they are forked before any thread
# (card clock, UI) exists in this process.
_CTX = mp.get_context("fork")
ALIVE_RECHECK_S = 0.001  # a dead producer is seen up to this long after it died (plus a cycle)
MESSAGE_WAIT_S = 0.05  # a stage's last message may still be in the queue's pipe this long


@dataclass
class RuntimeOptions:
    virtual_time: bool = False
    ring_seconds: float | None = None  # generator runs this far ahead (runtime.reference_buffer_s)
    blocks_fn: BlocksFn = blocks_source
    generate_fn: GenerateFn = reference_source
    drive: Drive | None = None  # an unopened drive (tests); default: the configured backend
    keep_drive_open: bool = False  # the caller owns `drive`, already open (the daemon)
    start_mm: tuple[float, float, float] | None = None  # where the machine is (default origin)
    settings: dict[str, Any] = field(default_factory=dict)  # MotionSettings overrides
    on_progress: Callable[[MotionProgress], None] | None = None
    rt_priority: int | None = MOTION_PRIORITY  # real time: try SCHED_FIFO for the motion thread
    optional_stop: bool = False  # M1 pauses like M0
    offsets: OffsetTable | None = None  # work offsets in force at the start (default none)
    from_line: int | None = None  # run from this line (interpreter state brought there)
    override_off_lines: list[list[int]] = field(default_factory=list)  # M49..M48 stretches
    probes: Any = None  # G38 results known (controller/probe.ProbeResults): a probing run
    probe_watch: Any = None  # watches the probe input (runtime/probe_run.ProbeWatch)
    on_event: Callable[[dict[str, Any]], None] | None = None  # output changes, as they happen


class _Messages:
    """Drains the info queue: stage error messages and each child's peak RSS."""

    def __init__(self, info: Any) -> None:
        self.info = info
        self.errors: dict[str, str] = {}
        self.rss_kb: dict[str, int] = {}
        self.sched: dict[str, str] = {}  # what each producer runs at ("nice -10")
        self.outputs: list[tuple] = []  # the changes of each output mark, in stream order
        self.sync_outputs: list[tuple] = []  # ... of each M62 mark (set as it is clocked)
        self.provisional: str | None = None  # a failure() given before its cause was in

    def drain(self, wait_s: float = 0.0, until: Callable[[], bool] | None = None) -> None:
        """Take the messages already sent; wait up to wait_s for more, unless until() holds
        (the message waited for is in: a stage's peak RSS is the last one it sends)."""
        deadline = time.monotonic() + wait_s
        while True:
            done = until is not None and until()
            try:
                kind, stage, value = self.info.get(
                    timeout=0.0 if done else max(0.0, deadline - time.monotonic()))
            except (queue.Empty, OSError, ValueError):
                return
            if kind in ("outputs", "sync_outputs"):
                getattr(self, kind).append(value)
                continue
            {"error": self.errors, "sched": self.sched}.get(kind, self.rss_kb)[stage] = value

    def failure(self) -> str:
        """Why the reference stream failed, once the failed stage's message is in (waited for
        at most MESSAGE_WAIT_S: it may still be in the queue's pipe). Given before the message
        that says why (the interpreter's error comes through its own feeder thread, which a
        loaded machine may run after the generator's), it is kept as provisional: see final()."""
        self.drain(MESSAGE_WAIT_S, until=lambda: "interpreter" in self.errors
                   or "generator" in self.rss_kb)
        if "interpreter" in self.errors:  # the generator only failed because its input did
            return f"{FAILED_MESSAGE}: {self.errors['interpreter']}"
        message = self.errors.get("generator", "reference generator failed")
        if message == "reference generator failed" or message.endswith(FAILED_MESSAGE):
            self.provisional = message
        return message

    def final(self, message: str) -> str:
        """message with a provisional failure replaced by the one the stages have sent since
        (called once the children are joined and their last messages drained)."""
        provisional, self.provisional = self.provisional, None
        if provisional is None or provisional not in message:
            return message
        return message.replace(provisional, self.failure(), 1)


class ExitCode:
    """A producer's exit code, None while it runs. Asked a few times every motion cycle, and in
    virtual time a cycle takes well under a millisecond: a running process is asked (a
    waitpid) at most every ALIVE_RECHECK_S."""

    def __init__(self, proc: Any) -> None:
        self.proc = proc
        self._alive_until_s = 0.0  # it ran when last asked: taken as running until then

    def code(self) -> int | None:
        if time.monotonic() < self._alive_until_s:
            return None
        code = self.proc.exitcode
        if code is None:
            self._alive_until_s = time.monotonic() + ALIVE_RECHECK_S
        return code  # type: ignore[no-any-return]


class RingSource:
    """RefSource over the shared ring; FAILED when the generator raised or died."""

    def __init__(self, ring: RefRing, generator: Any, messages: _Messages) -> None:
        self.ring, self.generator, self.messages = ring, generator, messages
        self._failure: str | None = None
        self._exit = ExitCode(generator)

    def read(self, max_rows: int) -> Any:
        return self.ring.read(max_rows)

    def state(self) -> tuple[SourceState, str]:
        flags = self.ring.flags
        if flags & FLAG_FINAL:
            return SourceState.FINISHED, ""
        if flags & FLAG_FAILED:
            if self._failure is None:  # asked every cycle of the stop: wait for it once
                self._failure = self.messages.failure()
            return SourceState.FAILED, self._failure
        code = self._exit.code()
        if code is not None:
            return SourceState.FAILED, f"reference generator process died (exit code {code})"
        return SourceState.STREAMING, ""

    def total_rows(self) -> int | None:
        return self.ring.written if self.ring.flags & FLAG_FINAL else None

    def next_outputs(self) -> tuple | None:
        """The next output mark's changes: sent before its rows, so in the pipe by now."""
        messages = self.messages
        messages.drain(MESSAGE_WAIT_S, until=lambda: bool(messages.outputs))
        return messages.outputs.pop(0) if messages.outputs else None

    def next_sync_outputs(self) -> tuple | None:
        """The next M62 mark's changes: sent before its rows, as next_outputs's."""
        messages = self.messages
        messages.drain(MESSAGE_WAIT_S, until=lambda: bool(messages.sync_outputs))
        return messages.sync_outputs.pop(0) if messages.sync_outputs else None

    def primed(self) -> bool:
        """The ring is full (the generator waits on it), or there is no more to wait for."""
        return (self.ring.available() >= self.ring.capacity or self.state()[0]
                is not SourceState.STREAMING)


class Runtime:
    """Runs one program; run() returns the MotionResult (extra: rss, start-up timings)."""

    def __init__(self, path: str, config: MachineConfig, options: RuntimeOptions | None = None):
        self.path, self.config = path, config
        self.options = options or RuntimeOptions()
        self.settings = MotionSettings.from_config(config, **self.options.settings)
        self.controller: MotionController | None = None
        self.procs: dict[str, Any] = {}
        # An abort asked before run() starts the controller (a signal during the check or a
        # homing before it): the controller is told at once, and nothing moves.
        self._abort_early: str | None = None

    def _generate_fn(self) -> GenerateFn:
        if self.options.optional_stop and self.options.generate_fn is reference_source:
            return functools.partial(reference_source, optional_stop=True)
        return self.options.generate_fn

    def request_resume(self) -> None:
        """Continue after a program pause (M0) or a feed hold."""
        if self.controller is not None:
            self.controller.request_resume()

    def request_hold(self) -> None:
        """Feed hold: decelerate along the path to a standstill (see motion.retime)."""
        if self.controller is not None:
            self.controller.request_hold()

    def set_feed_override(self, percent: float) -> None:
        """Feed override, 0-150 % (kept for a controller not yet started)."""
        self.feed_override_pct = percent
        if self.controller is not None:
            self.controller.set_feed_override(percent)

    feed_override_pct = 100.0

    def request_abort(self, message: str = "aborted by operator") -> None:
        if self.controller is not None:
            self.controller.request_abort(message)
        else:
            self._abort_early = message

    def run(self) -> MotionResult:
        t0_s = time.monotonic()
        n_cols = len(self.config.axes) + 2
        ring_s = self.options.ring_seconds or self.config.runtime.reference_buffer_s
        ring = RefRing.create(int(round(ring_s / self.config.sample_period_s)), n_cols)
        messages = _Messages(_CTX.Queue())
        rt = "off"
        thresholds = gc.get_threshold()
        try:
            # Built before the fork so that backend imports (scipy) are paid once, not per child.
            drive = self.options.drive or _build_drive(self.config, self.options.virtual_time)
            # Built (cached) before the fork: the generator plans with them and inherits them,
            # and the pacer's clock has not started (~4 ms pre-compensated: model inverse and
            # residual, which made the first cycle late).
            axis_servos(self.config)
            self._start(ring, messages)
            if self.options.virtual_time:  # no cycle waits on a collection (gc_policy.py)
                collect_less()
            if self.options.rt_priority is not None and not self.options.virtual_time:
                rt = try_realtime(self.options.rt_priority)
            if not self.options.keep_drive_open:
                open_drive(drive)
            try:
                result = self._motion(drive, ring, messages)
            finally:
                if not self.options.keep_drive_open:
                    drive.close()
                back_to_normal()
        finally:
            gc.unfreeze()  # (frozen by _start) a long-lived daemon's cycles are collected again
            gc.set_threshold(*thresholds)
            ring.set_flag(FLAG_ABORT)
            self._stop_children()
            # The children are joined: their last messages (peak RSS) are in the pipe.
            messages.drain(MESSAGE_WAIT_S, until=lambda: set(self.procs) <= set(messages.rss_kb))
            ring.close()
        result = replace(result, message=messages.final(result.message))
        result.extra["realtime"] = rt
        if rt != "off":
            producers = messages.sched.get("generator", "unknown")
            result.extra["scheduling"] = {**Scheduling(rt, producers).as_dict(),
                                          "interpreter": messages.sched.get("interpreter")}
        return self._finish(result, messages, t0_s)

    def _start(self, ring: RefRing, messages: _Messages) -> None:
        if self.options.blocks_fn is blocks_source or self.options.generate_fn is reference_source:
            preload_stages()
        blocks_fn = self.options.blocks_fn
        o = self.options
        if blocks_fn is blocks_source and (o.start_mm, o.offsets, o.from_line,
                                           o.probes) != (None,) * 4:
            blocks_fn = functools.partial(blocks_source, start_mm=o.start_mm, offsets=o.offsets,
                                          from_line=o.from_line, probes=o.probes)
        nc_fifo = _CTX.Queue(maxsize=self.config.runtime.nc_fifo_blocks)
        # Generator first, so that it is waiting on the NC FIFO when the first block lands.
        self.procs["generator"] = _CTX.Process(
            target=generator_main, name="cnc-generator", daemon=True,
            args=(self.config, self._generate_fn(), nc_fifo, ring, messages.info,
                  os.getpid()))
        self.procs["interpreter"] = _CTX.Process(
            target=interpreter_main, name="cnc-interpreter", daemon=True,
            args=(self.path, self.config, blocks_fn, nc_fifo, ring, messages.info,
                  os.getpid()))
        # Frozen, the objects held now are skipped by the children's collections, which then
        # neither scan them nor write to (so copy) their pages; the parent's stay frozen while
        # the motion runs (run() unfreezes them): its collections skip the program's blocks,
        # the config and the modules (some 100,000 objects on a 30,000-line program).
        gc.freeze()
        for proc in self.procs.values():
            proc.start()
        self._t_started_s = time.monotonic()

    def _watch(self, messages: _Messages) -> Callable[[], str | None]:
        interp = ExitCode(self.procs["interpreter"])
        found: list[str] = []

        def watch() -> str | None:
            # Called every motion cycle: a dead process is seen within a cycle (and
            # ALIVE_RECHECK_S). Its message is waited for once, not on every cycle of the stop
            # that follows.
            if found:
                return found[0]
            code = interp.code()
            if code is None or (code == 0 and "interpreter" not in messages.errors):
                return None
            messages.drain(MESSAGE_WAIT_S, until=lambda: "interpreter" in messages.rss_kb)
            if "interpreter" in messages.errors:
                found.append(f"{FAILED_MESSAGE}: {messages.errors['interpreter']}")
            else:
                found.append(f"NC interpreter process died (exit code {code})")
            return found[0]
        return watch

    def _motion(self, drive: Drive, ring: RefRing, messages: _Messages) -> MotionResult:
        source = RingSource(ring, self.procs["generator"], messages)
        period_s = self.config.sample_period_s
        watch = self._watch(messages)
        if self.options.probe_watch is not None:
            watch = self.options.probe_watch.wrap(watch, lambda: self.controller)
        if self.options.virtual_time:
            need = round((self.settings.high_water_ms + self.settings.holdback_ms) * 1e-3
                         / period_s) + 2 * self.settings.cycle_frames

            def ready() -> bool:
                # Rows produced but not yet executed (ring + held back + card FIFO) must cover
                # a full refill; otherwise virtual time waits for the generator.
                ctrl = self.controller
                ahead = ring.written - (ctrl.figures.executed if ctrl is not None else 0)
                aborted = ctrl is not None and (ctrl.abort_requested or ctrl.state not in (
                    MotionState.WAITING, MotionState.RUNNING))  # stopping needs no new rows
                starting = ctrl is None or not ctrl.stream.sent  # first motion: the ring full
                return ((ahead >= need and not (starting and not source.primed())) or aborted
                        or watch() is not None or source.state()[0] is not SourceState.STREAMING)
            # Blocks (motion/blocks.py) but where a probe is watched: its input is read each
            # cycle, and a block would run past the trip.
            until = getattr(drive, "advance_until", None) if self.options.probe_watch is None \
                else None
            pacer: Any = VirtualPacer(self.settings.cycle_frames, period_s, drive.advance,
                                      ready=ready, advance_until=until)
        else:
            pacer = WallPacer(self.settings.cycle_frames * period_s)
        self._pacer_t0_s = time.monotonic()
        self._pacer_t0_epoch_s = time.time()
        self.controller = MotionController(self.config, drive, source, pacer, self.settings,
                                           on_progress=self.options.on_progress,
                                           watch=watch, on_event=self.options.on_event)
        self.controller.set_feed_override(self.feed_override_pct)
        self.controller.set_override_off_lines(self.options.override_off_lines)
        if self.options.offsets is not None:
            origin = work_origin(self.options.offsets)
            self.controller.work_origin_mm = tuple(
                origin["xyz".index(a.name)] for a in self.config.axes)
        if self._abort_early is not None:
            self.controller.request_abort(self._abort_early)
        return self.controller.run()

    def _stop_children(self) -> None:
        for proc in self.procs.values():
            proc.join(timeout=0.5)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=0.5)
            if proc.is_alive():
                proc.kill()
                proc.join()

    def _finish(self, result: MotionResult, messages: _Messages, t0_s: float) -> MotionResult:
        import resource
        extra = dict(result.extra)
        extra["peak_rss_mb"] = {k: v / 1024 for k, v in messages.rss_kb.items()}
        extra["peak_rss_mb"]["motion"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        extra["process_start_s"] = self._t_started_s - t0_s
        first = result.time_to_first_motion_s
        if first is not None and not self.options.virtual_time:
            # Wall clock of the first executed frame (bench: launch-to-motion of `cncctl run`).
            extra["first_motion_epoch_s"] = self._pacer_t0_epoch_s + first
            first = (self._pacer_t0_s - t0_s) + first
        return replace(result, time_to_first_motion_s=first, extra=extra)


def build_drive(config: MachineConfig, virtual_time: bool) -> Drive:
    """The configured backend, not yet opened (virtual time: the sim card clocked by the loop)."""
    return _build_drive(config, virtual_time)


def _build_drive(config: MachineConfig, virtual_time: bool) -> Drive:
    try:
        return make_drive(config, realtime=not virtual_time)
    except DriveUnavailableError:
        raise
    except DriveError as exc:
        raise DriveUnavailableError(f"drive {config.drive.backend!r}: {exc}") from exc


def open_drive(drive: Drive) -> None:
    """Open (bring up) the drive; a failure here is before any motion."""
    try:
        drive.open()
    except DriveUnavailableError:
        raise
    except DriveError as exc:
        raise DriveUnavailableError(f"drive {drive.config.drive.backend!r} cannot be opened: "
                                    f"{exc}") from exc
