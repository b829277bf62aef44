"""The motion controller loop: keeps the card FIFO filled, checks feedback, stops under control.

Kept whole: MotionController is one run's state machine (streaming, pauses and holds, stops,
e-stop); its state lives in typed parts it owns (SendState: what a take-back restores,
RunFigures and RunChecks: what the result reads, OperatorRequests), and the steps that move
it between states stay methods of the one class instead of functions writing into it."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from controller.config import MachineConfig
from controller.errors import CncError, DriveError
from controller.motion.at_speed import AtSpeedWait
from controller.motion.blocks import BlockSend, CheckedAhead, block_frames
from controller.motion.checks import VIRTUAL_BATCH_ROWS, RefHistory, start_gap
from controller.motion.events import EventFn, JobEvents
from controller.motion.limits import LimitWatch
from controller.motion.outputs import OutputRunner
from controller.motion.pacing import VirtualPacer, WallPacer
from controller.motion.pulses import PulseCounter, counts_of
from controller.motion.ramp_first import HOLD_KEEP_MS, PLAN_BUDGET_MS, take_back_planned
from controller.motion.recall import SendState, Sent
from controller.motion.requests import OperatorRequests
from controller.motion.result import RunChecks, RunFigures, build_result
from controller.motion.retime import Retimer
from controller.motion.source import (
    RefSource,
    SourceState,
    is_output_mark,
    pause_index,
    row_lines,
)
from controller.motion.stopping import amax_stop_distances_mm, stop_along_path, with_lead_settled
from controller.motion.sync_outputs import SyncOutputs
from controller.motion.types import (
    MotionProgress,
    MotionResult,
    MotionSettings,
    MotionState,
    Outcome,
)
from controller.servo.precompensation import Precompensator
from drivers.base import CardStatus, Drive, Feedback
from drivers.errors import LostCommunicationError, UnderrunError

SETTLE_HOLD_S = 0.02  # encoder equal to the step counter for this long = settled
ESTOP_INPUT = "e-stop input on the drive tripped"
LIMIT_INPUT = "hard limit: {} tripped"
ESTOP_KEEP_MS = HOLD_KEEP_MS  # left in the card by the e-stop's take-back: a descheduling


class MotionController:
    """One instance runs one program: run() returns a MotionResult, never raises on faults.

    Every fault ends in a controlled stop (quintic decel along the buffered path, appended
    behind the frames already in the card) or, if the card itself halted, in a latched card
    fault; either way the final position is read back and pulses are accounted.
    """

    def __init__(self, config: MachineConfig, drive: Drive, source: RefSource,
                 pacer: WallPacer | VirtualPacer, settings: MotionSettings | None = None,
                 on_progress: Callable[[MotionProgress], None] | None = None,
                 watch: Callable[[], str | None] | None = None,
                 on_event: EventFn | None = None) -> None:
        self.config, self.drive, self.source, self.pacer = config, drive, source, pacer
        self.events = JobEvents(on_event)  # output changes (and other kinds) as they happen
        self.outputs = OutputRunner(drive, self.events)
        self.synced = SyncOutputs(drive, self.outputs, config.sample_period_s)  # M62/M63/M67
        self.settings = settings or MotionSettings.from_config(config)
        self.on_progress = on_progress
        self.watch = watch  # external health check (dead processes): message -> stop
        self.n = len(config.axes)
        self.period_s = config.sample_period_s
        self.pulse_mm = np.array([a.pulse_mm for a in config.axes])
        self.retimer = Retimer(config)
        self.requests = OperatorRequests()
        self.work_origin_mm: tuple[float, ...] = ()  # for the progress reports' work position
        self.keep_outputs_at_abort = False  # a probe's trip: its abort ends a stretch, not the job

    def frames_for_ms(self, ms: float) -> int:
        return max(1, math.ceil(ms * 1e-3 / self.period_s - 1e-9))

    def take_back_beyond_ms(self, keep_ms: float) -> bool:
        """Streaming, and not coming to rest anyway (the stream's end, a pause, the tail): the
        frames queued beyond keep_ms are taken back where the drive can (e-stop, probe trip)."""
        at_rest = self.sent_eos or self.pausing or self.pending_tail is not None
        if self.state not in (MotionState.WAITING, MotionState.RUNNING) or at_rest:
            return False
        self.stream.take_back_now(self.drive, self.frames_for_ms(keep_ms))
        return True

    # -- main loop ------------------------------------------------------------------------
    def run(self) -> MotionResult:
        self._setup()
        while self.state is not MotionState.FINISHED:
            self._wait()
            self._cycle()
        if self.outcome not in (Outcome.DONE, None) and not (
                self.outcome is Outcome.ABORTED and self.keep_outputs_at_abort):
            self._outputs_safe()  # abort, e-stop, fault: spindle, coolant, outputs safe
        self._disable_drives()  # after an e-stop's stop: category 1
        return self._result()

    def _outputs_safe(self) -> None:
        problem = self.outputs.to_safe(self.figures.executed * self.period_s, self.figures.line)
        if problem is not None:
            self._then_fault(problem)

    def _setup(self) -> None:
        start_cmd, start_enc = self.drive.position_counts()
        self.figures = RunFigures(start_cmd=start_cmd, last_enc=start_enc)
        # Clocked in real time: smaller refills (the FIFO stays nearer its high-water mark,
        # where a late wake-up under load takes it from) and statistics batches.
        virtual = isinstance(self.pacer, VirtualPacer) and self.pacer.blocks
        batch = VIRTUAL_BATCH_ROWS if virtual else None
        self.checks = RunChecks.start(self.config, start_cmd, start_enc,
                                      self.settings.in_position_mm, batch)
        start_mm = start_cmd * self.pulse_mm
        precomp = (Precompensator([a.servo for a in self.config.axes], self.period_s, start_mm)
                   if self.config.interpolator.servo_precompensation else None)
        self.stream = SendState(
            held=np.zeros((0, self.n + 2)), prev_mm=start_mm, last_mm=start_mm,
            retimer=self.retimer, pulses=PulseCounter(self.pulse_mm, start_cmd),
            hist=RefHistory(2 * self.drive.fifo_capacity() + 1024, self.n, self.period_s),
            precomp=precomp)
        self.ahead = CheckedAhead(self.checks, self.stream.hist, self._own_numbers,
                                  self.drive if isinstance(self.pacer, WallPacer) else None)
        self.pending_stop = np.zeros((0, self.n))
        self.state = MotionState.WAITING
        self.outcome: Outcome | None = None
        self.message = ""
        self.sent_eos = False
        self.block_early_s = 0.0  # see _wait
        self.next_progress_s = 0.0
        self.settle_deadline_s = 0.0
        self.position_known = True
        self.pausing = False  # the frames up to a program pause are sent: wait there
        self.holding = False  # feed hold asked: decelerate along the path, then wait
        self.program_pause = False  # the standstill being reached is a program pause (M0)
        self.output_mark: int | None = None  # the standstill being reached sets outputs: line
        self.restarting = False  # resumed from a pause: the FIFO is empty by design
        self.seq0: int | None = None  # the drive's number of this run's first frame
        self.pending_tail: tuple | None = None  # a stream's end at rest still to go out
        self.estop_reason: str | None = None  # the e-stop under way (then disable)
        self.limits = LimitWatch(self.drive, self.config.axis_names, start_mm)
        self.at_speed = AtSpeedWait(self.config.io.spindle, self.drive, self.pacer.elapsed_s)
        s = self.settings
        span = (self.frames_for_ms(s.high_water_ms) - self.frames_for_ms(s.low_water_ms)
                - s.cycle_frames)
        self.block = block_frames(s.block_ms, self.period_s, s.cycle_frames, span)
        self.refill = self.block if virtual else block_frames(s.refill_ms, self.period_s,
                                                              s.cycle_frames, span // 2)

    def _wait(self) -> None:
        """The cycle's wait; in virtual time, while the stream runs steadily, a block of
        frames at once (motion/blocks.py), no more than the FIFO holds above its low mark."""
        self.block_early_s = 0.0
        if not (isinstance(self.pacer, VirtualPacer) and self.pacer.blocks and self._steady()):
            self.pacer.wait()
            return
        try:
            room = self.drive.fifo_level() - self.frames_for_ms(self.settings.low_water_ms)
        except DriveError:  # the cycle reads it again and stops on it
            room = 0
        cycle = self.settings.cycle_frames
        frames = min(self.block, room) // cycle * cycle
        if frames <= cycle:
            self.pacer.wait()
            return
        clocked = self.pacer.wait_block(frames, self.ahead.cut)  # blocks.py
        # The block's first cycle ended this much before its last (the first motion's time).
        self.block_early_s = (clocked - cycle) * self.period_s

    def _steady(self) -> bool:
        """Streaming at the program's own pace, nothing asked or under way that a cycle must
        see within its two frames (a stop, a pause, a hold, an override, the stream's end)."""
        r = self.requests
        return (self.state is MotionState.RUNNING and self.outcome is None and not self.sent_eos
                and not self.pausing and not self.holding and not self.restarting
                and self.pending_tail is None and self.retimer.identity and not r.hold
                and not r.resume and r.abort_message is None and r.estop_message is None
                and self.estop_reason is None and not self.synced.pending
                and not self.synced.written)  # M62's outputs: set and reported per cycle

    def _cycle(self) -> None:
        try:
            raw, status, level = self.drive.feedback(), self.drive.status(), self.drive.fifo_level()
        except LostCommunicationError as exc:
            self.position_known = False
            self._finish(Outcome.FAULT, str(exc))
            return
        fb, bad, checked = self.ahead.believed(raw, settling=status.halted)  # (blocks.py)
        if bad is not None:  # a reading no drive could give: none believed from then on
            self.position_known = False
            self._begin_stop(Outcome.FAULT, bad.message)
        self._account(fb)
        if (problem := self.synced.due(self.figures.executed, self.stream.sent)) is not None:
            self._begin_stop(Outcome.FAULT, problem)
        if status.halted:
            self.figures.underruns += int(CardStatus.UNDERRUN in status)
            self._finish(Outcome.FAULT, self.drive.fault_message())
            return
        self._supervise(fb, checked)
        self._check_estop()
        level = self._operator_requests(level)
        if self.pending_tail is not None:
            self._send_tail(level)  # a stream's last frames, the lead settling: nothing first
        elif self.pausing and self.outcome is None:
            self._pause_step(level)
        elif self.state in (MotionState.WAITING, MotionState.RUNNING) and not self.sent_eos:
            self._refill(level)
        elif self.state is MotionState.STOPPING:
            self._send_stop(level)
        self._settle(level, fb)
        self._report(level)

    def _own_numbers(self, fb: Feedback) -> Feedback:
        """Frame numbers of this run from 0: a drive kept open (cncd, a run from line after
        its approach) numbers frames since it was opened. The FIFO is idle when a run starts,
        so the first frame fed back is this run's first."""
        if not len(fb):
            return fb
        if self.seq0 is None:
            self.seq0 = int(fb.seq[0])
        if not self.seq0:
            return fb
        return Feedback(fb.seq - self.seq0, fb.commanded_counts, fb.encoder_counts)

    def _account(self, fb: Feedback) -> None:
        if not len(fb):
            return
        now_s = self.pacer.elapsed_s()
        if self.figures.first_motion_s is None:
            early_s = self.block_early_s  # virtual time: whole cycles (no float residue)
            self.figures.first_motion_s = round(now_s - early_s, 9) if early_s else now_s
        self.figures.last_motion_s = now_s
        self.figures.executed = int(fb.seq[-1]) + 1
        self.figures.last_enc = fb.encoder_counts[-1]
        self.figures.line = int(self.stream.hist.line[fb.seq[-1] % self.stream.hist.capacity])
        self.checks.contour.update(fb, self.stream.hist)
        self.checks.model.update(fb.seq, fb.commanded_counts, fb.encoder_counts,
                                 self.stream.hist)
        self.checks.in_position.frames(fb.seq, fb.encoder_counts, self.stream.pulses.counts)

    def _supervise(self, fb: Feedback, checked: bool = False) -> None:
        trip = None if checked else self.checks.ferr.check(fb, self.stream.hist)
        if trip is not None:
            line = int(self.stream.hist.line[trip.seq % self.stream.hist.capacity])
            self._begin_stop(Outcome.FAULT, f"{trip.axis.upper()} axis following error "
                             f"{abs(trip.ferror_mm):.3f} mm > limit {trip.limit_mm:.3f} mm "
                             f"at line {line}")
        problem = self.watch() if self.watch is not None else None
        if problem:
            self._begin_stop(Outcome.FAULT, problem)
        if self.requests.abort_message is not None:
            self._begin_stop(Outcome.ABORTED, self.requests.abort_message)
        self.ahead.plan.plan_next()  # real time: the card's next block, checked once

    def _operator_requests(self, level: int) -> int:
        """Hold and override become the re-timer's target rate (resume: see _pause_step); a
        slower one is planned first, then what the card has queued beyond it is taken back
        (motion/ramp_first.py). Returns the FIFO level after it (the refill that follows
        writes the ramp at once)."""
        before = self.retimer.wanted
        if self.requests.hold and not self.holding:
            self.holding = True
        self.requests.hold = False
        if self.requests.resume and self.holding and not self.pausing:
            self.holding = False  # resumed before the standstill: ramp back up from here
            self.requests.resume = False
        override = self.requests.override_pct / 100.0 if self._override_allowed() else 1.0
        rate = 0.0 if self.holding else override
        if rate < before and self.state is MotionState.RUNNING and not self.pausing \
                and self.outcome is None:
            level = take_back_planned(self.stream, self.drive, level, rate,
                                      self.frames_for_ms(HOLD_KEEP_MS),
                                      self.frames_for_ms(PLAN_BUDGET_MS), self._read_ahead)
        self.retimer.set_target(rate)
        return level

    # -- streaming ------------------------------------------------------------------------
    def _refill(self, level: int) -> None:
        if self.state is MotionState.WAITING and not self.stream.sent \
                and not getattr(self.source, "primed", lambda: True)():
            return  # first motion once the reference buffer is full or planned to its end
        s = self.settings
        want = self.frames_for_ms(s.high_water_ms) - level
        hold, low = self.frames_for_ms(s.holdback_ms), self.frames_for_ms(s.low_water_ms)
        if self.state is MotionState.RUNNING and not self.restarting:
            low_fifo = self.figures.min_fifo_frames
            self.figures.min_fifo_frames = level if low_fifo is None else min(level, low_fifo)
        self.restarting = self.restarting and level == 0  # after a pause: empty until refilled
        if self.state is MotionState.RUNNING and not self.restarting and want < self.refill:
            state, problem = self.source.state()  # a failed producer is seen every cycle
            if state is SourceState.FAILED:
                self._begin_stop(Outcome.FAULT, problem)
            return  # a block at a time: the FIFO holds more than high water less a block
        finished_before, _ = self.source.state()
        ask = max(0, want + hold - len(self.stream.held))
        rows = self.synced.take(self.source.read(ask) if ask else np.zeros((0, self.n + 2)),
                                self.source)
        # Final only when a read came back short after the producer had finished.
        final = finished_before is SourceState.FINISHED and 0 < ask and len(rows) < ask
        state, problem = self.source.state()
        if state is SourceState.FAILED:
            self._begin_stop(Outcome.FAULT, problem)
            return
        if len(rows) and not self._start_ok(rows):
            return
        self.stream.held = np.vstack([self.stream.held, rows]) if len(rows) else self.stream.held
        if not self.retimer.identity and not final and ask:
            self._read_ahead()  # a ramp is planned on the rows it will cross
        pause = pause_index(self.stream.held) if len(self.stream.held) else None
        sendable = len(self.stream.held) if final else max(0, len(self.stream.held) - hold)
        if self.state is MotionState.WAITING and not final and len(self.stream.held) < hold + low:
            sendable = 0  # prime: first motion only with enough reference behind it
        # Everything up to a pause goes out whatever the holdback: the path is at rest there
        # (a stop along it is not needed), and the card idles after it, no underrun.
        limit = pause + 1 if pause is not None else sendable
        before = self.stream.before_send()
        as_they_are = self.retimer.identity  # rows out as they are: a block in pieces
        out, used = self.retimer.take(self.stream.held, limit, max(want, 0),
                                      land=pause is not None or final)
        held = self.stream.held
        consumed, self.stream.held = held[:used].copy(), held[used:]  # (journal: a copy)
        whole = self.retimer.frac == 0.0
        at_pause = pause is not None and used == pause + 1 and whole
        at_hold = self.retimer.at_rest and not at_pause
        mark = at_pause and is_output_mark(float(held[pause, -1]))  # type: ignore[index]
        if mark:
            self.output_mark = int(row_lines(held[pause:pause + 1])[0])  # type: ignore[misc]
        self.program_pause = self.program_pause or (at_pause and not mark)
        end = final and not len(self.stream.held) and whole
        every = self.settings.cycle_frames if as_they_are else 0
        self._send(out, end=end, pause=at_pause or at_hold)
        if end or at_pause or at_hold:
            self.stream.journal.clear()  # the card ends its stream there: nothing to take back
        else:
            self._journal(out, consumed, before, every)
        if self.stream.sent and not final and pause is None and not self.pausing \
                and level + len(out) < low:
            self._begin_stop(Outcome.FAULT, f"feed hold at line {self.figures.line}: reference "
                             "points ran late (generator starved), stopped along the path")

    def _journal(self, out: np.ndarray, consumed: np.ndarray, before: Sent, every: int) -> None:
        """A send in the journal; a block sent as it is, in pieces of `every` (blocks.py)."""
        if not every or len(out) <= every:
            self.stream.journal.record(len(out), consumed, before)
            return
        counts = self.stream.hist.counts_copy(before.hist_count, len(out))
        block = BlockSend(before, consumed, counts, self.stream.precomp)  # type: ignore[arg-type]
        self.stream.journal.record_block(block, every)  # its pieces made if a take-back looks

    def _read_ahead(self, max_rows: int = 4096) -> None:
        """More held rows while re-timing: a ramp looks at the rows it will cross."""
        if len(self.stream.held) < max_rows:
            rows = self.synced.take(self.source.read(max_rows - len(self.stream.held)),
                                    self.source)
            if len(rows):
                self.stream.held = np.vstack([self.stream.held, rows])

    def _start_ok(self, rows: np.ndarray) -> bool:
        """The first reference point must be where the machine is (no jump at start), and the
        first rows must not go further onto a limit switch open since before the start."""
        if self.stream.sent or len(self.stream.held):
            return True
        first_step_mm = (0.5 * self.config.interpolator.max_accel_mm_s2 * self.period_s ** 2
                         * (1.0 + 1e-6))
        problem = start_gap(rows[0, : self.n], self.figures.start_cmd, self.pulse_mm,
                            first_step_mm)
        problem = problem or self.limits.refuses(rows[:, : self.n])
        if problem is not None:
            self._finish(Outcome.FAULT, problem)
        return problem is None

    def _send(self, rows: np.ndarray, end: bool, pause: bool = False) -> None:
        """Wanted rows (position, feed, line) out as they are or pre-compensated, a stream's end
        with the lead's settling (what exceeds the high-water mark goes out in later cycles)."""
        pos = rows[:, : self.n]
        cmd = pos if self.stream.precomp is None else self.stream.precomp.push(pos)
        if self.stream.precomp is not None and (end or pause):
            wanted = len(rows)
            rows, cmd = with_lead_settled(self.stream.precomp, rows, cmd,  # type: ignore[arg-type]
                                          self.stream.last_mm, self.figures.line)
            self.figures.lead_frames += len(rows) - wanted
            room = max(0, self._tail_room() - self.drive.fifo_level())
            if len(cmd) > room:
                self.pending_tail = (rows[room:], cmd[room:], end, pause)
                rows, cmd, end, pause = rows[:room], cmd[:room], False, False
        self._write(rows, cmd, end, pause)

    def _send_tail(self, level: int) -> None:
        rows, cmd, end, pause = self.pending_tail  # type: ignore[misc]
        room = max(0, self._tail_room() - level)
        last = len(cmd) <= room
        self.pending_tail = None if last else (rows[room:], cmd[room:], end, pause)
        self._write(rows[:room], cmd[:room], end and last, pause and last)

    def _tail_room(self) -> int:  # the high-water mark, as refills; a stop fills the card
        cap = self.drive.fifo_capacity() - 1
        return cap if self.outcome else min(self.frames_for_ms(self.settings.high_water_ms), cap)

    def _write(self, rows: np.ndarray, cmd: np.ndarray, end: bool, pause: bool) -> None:
        pos = rows[:, : self.n]
        if len(pos):
            feed = rows[:, self.n] if rows.shape[1] > self.n else np.zeros(len(pos))
            line = row_lines(rows) if rows.shape[1] > self.n + 1 else np.full(len(pos),
                                                                              self.figures.line)
            self.stream.hist.append(pos, feed, line.astype(np.int64), self.stream.last_mm,
                                    counts_of(cmd, self.pulse_mm))
            self.stream.prev_mm = pos[-2] if len(pos) > 1 else self.stream.last_mm
            self.stream.last_mm = pos[-1].copy()
            self.state = MotionState.RUNNING if self.state is MotionState.WAITING else self.state
        if len(pos) or end or pause:
            counts = self.stream.pulses.counts
            try:
                self.drive.write_frames(self.stream.pulses.frames(cmd), end_of_stream=end or pause)
            except DriveError as exc:
                self.stream.pulses.counts = counts  # these frames were never queued
                self._write_failed(exc)
                return
            if len(pos) and (self.synced.pending or self.synced.written):  # M62: see there
                self.synced.on_write(line, self.stream.sent)
        self.stream.sent += len(pos)
        self.sent_eos = self.sent_eos or end
        self.pausing = self.pausing or pause

    def _write_failed(self, exc: DriveError) -> None:
        if isinstance(exc, LostCommunicationError):
            self.position_known = False
        # The card halted since this cycle read its status (an underrun after a stall of
        # the host, an amplifier fault): as a halt read at the cycle's start, not an
        # exception out of the loop with no result and no position.
        self.figures.underruns += int(isinstance(exc, UnderrunError))
        self._finish(Outcome.FAULT, str(exc))

    def _pause_step(self, level: int) -> None:
        """At a program pause or a hold: PAUSED/HELD once the card has run out, RUNNING again
        on resume (from a hold: a planned ramp back to the override's feed). A standstill
        of 0 % override goes on by itself once the override is turned up."""
        if self.state not in (MotionState.PAUSED, MotionState.HELD):
            if self.at_speed.waiting and (not self._at_speed_reached() or not self.holding):
                return  # standing at the spindle start; then going on (or held, or a fault)
            if level == 0 and self.output_mark is not None:
                if not self._set_outputs(self.output_mark) or not self.holding:
                    return  # set and going on (or a fault); held there: held as below
            if level == 0:
                self.state = MotionState.PAUSED if self.program_pause else MotionState.HELD
                self.requests.resume = False  # a resume must come after the standstill
            return
        zero_override_lifted = (self.state is MotionState.HELD and not self.holding
                                and self.requests.override_pct > 0.0)
        if not (self.requests.resume or zero_override_lifted):
            self.pacer.idle()
        if self.requests.resume or zero_override_lifted:
            self.requests.resume = False
            self.pausing = False
            self.program_pause = False
            self.restarting = True
            self.holding = False
            self.state = MotionState.RUNNING

    def _set_outputs(self, line: int) -> bool:
        """At an output mark, the card run out (the machine stands there): set the outputs,
        then go on unless a feed hold came to rest there (the spin-up wait is planned rows
        after the mark). False: they could not be set, and the job stops, or the machine now
        waits there for the spindle's at-speed input (controller/motion/at_speed.py)."""
        self.output_mark = None
        changes = getattr(self.source, "next_outputs", lambda: None)()
        problem = self.outputs.at_mark(changes, self.figures.executed * self.period_s, line)
        if problem is not None:
            self._begin_stop(Outcome.FAULT, problem)
            return False
        if self.at_speed.begin(changes, line):
            return False
        self._go_on()
        return True

    def _at_speed_reached(self) -> bool:
        """Waiting at a spindle start: True once the input is true (going on unless held)."""
        problem = self.at_speed.poll()
        if problem is not None:
            self._begin_stop(Outcome.FAULT, problem)
            self.message = problem  # (not "program pause ...; then": no pause was asked)
        if problem is not None or self.at_speed.waiting:
            return False
        self._go_on()
        return True

    def _go_on(self) -> None:
        if not self.holding:
            self.pausing = False
            self.restarting = True

    # -- stops otherwise than planned: a fault during a stop, the e-stop ------------------
    def _asked(self) -> str:
        """The stop under way when nothing went wrong yet (a fault then names it too)."""
        if self.holding:
            return f"feed hold at line {self.figures.line}"
        if self.pausing:
            return f"program pause at line {self.figures.line}"
        return "program end" if self.sent_eos else ""

    def _then_fault(self, message: str) -> None:
        """A fault during a stop (abort, e-stop, hold, program end) is a fault: it says what
        was asked and what happened (an abort's fault was reported as an abort, and the daemon
        went IDLE on a faulted drive)."""
        before = self.message if self.outcome is not None else self._asked()
        if before and message in before:
            return
        self.outcome = Outcome.FAULT
        self.message = f"{before}; then {message}" if before else message

    def _check_estop(self) -> None:
        """Each cycle: an e-stop asked, or the drive's e-stop input open, starts the e-stop
        (a category 1 stop: the fastest the drives allow, along the path, then disabled)."""
        if self.estop_reason is not None:
            return
        reason = self.requests.estop_message
        if reason is None and self.drive.estop_input():
            reason = ESTOP_INPUT
        limit = self.limits.tripped(self.stream.last_mm) if reason is None else None
        if limit is not None:  # a hard limit: the same category 1 stop, latched as a fault
            reason = LIMIT_INPUT.format(limit)
        if reason is not None:
            self.estop_reason = reason
            self._begin_estop(reason)
        if limit is not None:
            self.outcome = Outcome.FAULT

    def _begin_estop(self, reason: str) -> None:
        if self.outcome is None or self.outcome is Outcome.DONE:
            self.outcome, self.message = Outcome.ABORTED, reason
        elif reason not in self.message:
            self.message = f"{self.message}; then {reason}"
        if not self.stream.sent:
            self.state = MotionState.FINISHED  # nothing moved
            return
        accel = self.config.interpolator.max_accel_mm_s2
        st = self.stream
        if self.state is MotionState.STOPPING:
            # An abort's stop: its rows not yet sent are re-timed at Amax along themselves.
            # Once all are sent (the stream has ended) nothing is added: the card stops where
            # they end.
            if len(self.pending_stop) and not self.sent_eos:
                self.pending_stop = stop_along_path(st.prev_mm, st.last_mm, self.pending_stop,
                                                    accel, self.period_s, amax_stop_distances_mm)
            return
        # The stop starts ESTOP_KEEP_MS out, not behind the whole FIFO (2 ms ran a loaded card
        # dry), from the level now: the cycle's was read before its checks ran.
        if self.take_back_beyond_ms(ESTOP_KEEP_MS):
            self.pending_stop = stop_along_path(st.prev_mm, st.last_mm, st.held[:, : self.n],
                                                accel, self.period_s, amax_stop_distances_mm)
            st.held = st.held[:0]
            self.state = MotionState.STOPPING
            return
        if self.state in (MotionState.PAUSED, MotionState.HELD, MotionState.RUNNING):
            # At rest, or coming to rest where the stream ends: settle there, then disable.
            self.state = MotionState.SETTLING
            self.settle_deadline_s = self.pacer.elapsed_s() + self.settings.settle_s

    def _disable_drives(self) -> None:
        """After the e-stop's stop: the drives disabled (a failure to is a fault, named)."""
        if self.estop_reason is None:
            return
        try:
            self.drive.disable()
        except CncError as exc:
            self._then_fault(f"the drives could not be disabled: {exc}")

    def _begin_stop(self, outcome: Outcome, message: str) -> None:
        if self.outcome is not None:
            # The first reason stays; a fault during an abort's stop makes it a fault.
            if outcome is Outcome.FAULT and self.outcome is not Outcome.FAULT:
                self._then_fault(message)
            return
        if outcome is Outcome.FAULT:
            self._then_fault(message)
        else:
            self.outcome, self.message = outcome, message
        if self.sent_eos or self.pausing or not self.stream.sent or self.pending_tail is not None:
            self.state = MotionState.SETTLING if self.stream.sent else MotionState.FINISHED
            return
        st = self.stream
        self.pending_stop = stop_along_path(st.prev_mm, st.last_mm, st.held[:, : self.n],
                                            self.config.interpolator.max_accel_mm_s2,
                                            self.period_s)
        self.stream.held = np.zeros((0, self.n + 2))
        self.state = MotionState.STOPPING

    def _send_stop(self, level: int) -> None:
        space = max(0, self.drive.fifo_capacity() - level - 1)
        rows, self.pending_stop = self.pending_stop[:space], self.pending_stop[space:]
        self._send(rows, end=not len(self.pending_stop))

    def _settle(self, level: int, fb: Feedback) -> None:
        if self.state is MotionState.WAITING and self.sent_eos and not self.stream.sent:
            self._finish(self.outcome or Outcome.DONE, self.message)  # a program that never
            return  # moves (G-code without motion, a jog of zero length): done at once
        if self.state in (MotionState.RUNNING, MotionState.STOPPING) and self.sent_eos \
                and level == 0:
            self.state = MotionState.SETTLING
            self.settle_deadline_s = self.pacer.elapsed_s() + self.settings.settle_s
        if self.state is not MotionState.SETTLING or self.pending_tail is not None:
            return
        cmd, enc = self.drive.position_counts()
        now_s = self.pacer.elapsed_s()
        f = self.figures
        if f.executed:  # the settling: where the tool overshoots a stop
            self.checks.contour.update_at(np.array([f.executed - 1]), enc, self.stream.hist)
        if f.first_motion_s is not None:
            self.checks.in_position.at_rest(enc, cmd, now_s - f.first_motion_s + self.period_s)
        # Equal once is not settled: the 36 % overshoot crosses the target on its way.
        if not np.array_equal(cmd, enc):
            self.figures.settled_since_s = None
        elif self.figures.settled_since_s is None:
            self.figures.settled_since_s = now_s
        held_s = 0.0 if f.settled_since_s is None else now_s - f.settled_since_s
        if held_s >= SETTLE_HOLD_S or now_s >= self.settle_deadline_s:
            self._finish(self.outcome or Outcome.DONE, self.message)

    def _finish(self, outcome: Outcome, message: str) -> None:
        if outcome is Outcome.FAULT and message:
            self._then_fault(message)
        elif self.outcome is None or self.outcome is Outcome.DONE:
            self.outcome, self.message = outcome, message
        self.state = MotionState.FINISHED

    # -- reporting ------------------------------------------------------------------------
    def _report(self, level: int) -> None:
        now_s = self.pacer.elapsed_s()
        if self.on_progress is None or (now_s < self.next_progress_s
                                        and self.state is not MotionState.FINISHED):
            return
        self.next_progress_s = now_s + self.settings.progress_every_s
        self.on_progress(self._progress(level, now_s))

    def _result(self) -> MotionResult:
        self.ahead.plan.catch_up()  # the checks' figures to the last row read
        result = build_result(self.config, self.figures, self.checks, self.outcome,
                              self.message, self.stream.pulses.commanded_counts,
                              self.stream.sent, self.pacer.late_cycles, self.drive)
        if self.events.count:
            result.extra["events"] = self.events.kept
        if self.drive.is_open:
            result.extra["outputs"] = self.drive.outputs()
        return result

    def _progress(self, level: int, now_s: float) -> MotionProgress:
        """Where the run is: state, line, feed, following error, card FIFO (level frames),
        time."""
        f, hist = self.figures, self.stream.hist
        self.ahead.plan.catch_up()  # its following error is the last row's
        total = self.source.total_rows()
        idx = (f.executed - 1) % hist.capacity
        return MotionProgress(
            state=self.state, line=f.line,
            feed_mm_s=float(hist.feed_mm_s[idx]) if f.executed else 0.0,
            ferror_um=float(np.abs(self.checks.ferr.last_mm).max()) * 1e3,
            fifo_ms=level * self.period_s * 1e3, elapsed_s=now_s,
            executed_s=f.executed * self.period_s,
            planned_s=None if total is None else total * self.period_s,
            override_pct=self.requests.override_pct,
            position_mm=tuple(float(v) for v in f.last_enc * self.pulse_mm),
            work_origin_mm=self.work_origin_mm)

    # -- the operator's requests (see OperatorRequests) ------------------------------------
    def request_resume(self) -> None:
        self.requests.request_resume()

    def request_hold(self) -> None:
        self.requests.request_hold()

    def set_override_off_lines(self, spans: list[list[int]]) -> None:
        self.requests.set_override_off_lines(spans)

    def set_feed_override(self, percent: float) -> None:
        self.requests.set_feed_override(percent)

    def request_abort(self, message: str = "aborted by operator") -> None:
        self.requests.request_abort(message)

    def request_estop(self, message: str = "e-stop") -> None:
        self.requests.request_estop(message)

    @property
    def abort_requested(self) -> bool:
        return self.requests.abort_requested

    def _override_allowed(self) -> bool:
        if not self.requests.override_off:
            return True
        held = self.stream.held
        line = int(row_lines(held[:1])[0]) if len(held) else self.figures.line
        return self.requests.override_allowed(line)
