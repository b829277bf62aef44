"""The `sim` backend: a simulated bit-pattern pulse card with a frame FIFO and servo axes.

Kept whole: SimCard because its hooks share one lock, one frame clock and one FIFO (what a
simulated input needs of it, such as the spindle's at-speed input, lives in drivers/sim/)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from controller.blocks import OutputChange
from controller.config import MachineConfig
from controller.outputs import OutputImage
from controller.servo.plant_option import PLANT_OPTIONS
from drivers.at_speed_input import AtSpeedInput
from drivers.base import CardStatus, Drive, Feedback
from drivers.errors import BadFrameError, DriveError, HomingError, LostCommunicationError
from drivers.frame_outputs import FrameOutputQueue, FrameOutputs
from drivers.homing import plan_for
from drivers.io_peer import (
    IO_OPTIONS,
    limit_tripped,
    record_outputs,
    switch_name,
    workpiece_option,
)
from drivers.sim.ahead import AheadClock
from drivers.sim.axes import SimAxes, plant_of
from drivers.sim.block_clock import BlockClock
from drivers.sim.fifo import FrameFifo
from drivers.sim.homing import SimAxesHoming
from drivers.sim.spindle import SimSpindle, spinup_option
from drivers.sim.switches import SimSwitches, timeout_message

REST_AFTER_S = 2.0  # idle this long, the Table II servo has settled (poles of ~100/s and up)
# The real-time clock thread wakes this often (see _clock_thread); every call clocks what fell
# due first, so a host reading each cycle sees the card as if clocked period by period.
WAKE_EVERY_S = 0.008


class SimCard(BlockClock, AheadClock, Drive, FrameOutputs, AtSpeedInput):
    """Frames are clocked one per sample period T, in wall-clock time or virtual time.

    Options: realtime (bool, default True), fifo_frames (256), max_pulses_per_frame (127,
    an int8 frame as in the prototype protocol), start_mm (list, what the counters read at
    power-up), plant_x, plant_y, plant_z (a0,a1,a2,a3,a4,b0,b1,b2: the axis's own eq. 27 loop
    instead of the config's model), plant_pole_pct and plant_gain_pct (0: a plant off the
    planner's model, see mismatched, on top of any plant_<axis>; servo/plant_option.py).
    Homing (drivers/sim/homing.py): true_start_mm (list, where the table really is at
    power-up; default start_mm), home_switch_mm (list, where each axis's home switch is,
    in that true frame; default each axis's homing home_mm, null: no switch), index_pitch_mm
    (1.0, encoder index marks at its multiples) and homed_at_start (false). E-stop input:
    estop_input_file (a path: the input reads tripped while that file exists, so that a
    test in another process can trip it; trip_estop_input() does it in-process);
    drive_fault_file (a path: X's amplifier faults, latched, once that file exists).
    Machine I/O (drivers/io_peer.py): limit_input_file (while it exists, the limit switch it
    names, "x+", is tripped; trip_limit_input() in-process) and outputs_file (the outputs
    written there as JSON each time they change); the outputs are kept as `output_image`;
    spindle_spinup_s (0; "never"): the at-speed input comes true that long after a start.
    Card rule (hostmot2 watchdog): an empty FIFO mid-program stops the card and latches
    UNDERRUN until reset(); an empty FIFO after an end-of-stream frame is simply idle.

    In real time the frames are clocked in blocks: each call (and each inject_*) first clocks
    every period that fell due by now, and a thread wakes every WAKE_EVERY_S (every period
    while homing or while outputs wait for their frame) for those no call asked about.
    Between two calls nothing the card holds changes, so a frame is clocked as it would have
    been at its own period: one written after its period is as late as ever (an underrun at
    that frame), and the host reads the same rows, status and level.
    """

    OPTIONS = frozenset({"realtime", "fifo_frames", "max_pulses_per_frame", "start_mm",
                         "true_start_mm", "home_switch_mm", "index_pitch_mm", "homed_at_start",
                         "estop_input_file", "drive_fault_file", "probe_workpiece_mm"}) \
        | PLANT_OPTIONS | IO_OPTIONS
    at_speed_input_name = "sim card, option spindle_spinup_s"

    def __init__(self, config: MachineConfig, **options: Any) -> None:
        super().__init__(config, **options)
        self.period_s = config.sample_period_s
        self._rest_frames = max(1, round(REST_AFTER_S / self.period_s))  # see _sleep_at_rest
        self.realtime = bool(options.get("realtime", True))
        self.max_pulses = int(_option(options, "max_pulses_per_frame", 127, 1, 32767))
        start_mm = np.asarray(options.get("start_mm", np.zeros(self.n_axes)), dtype=float)
        self._fifo = FrameFifo(int(_option(options, "fifo_frames", 256, 16, 1_000_000)),
                               self.n_axes)
        # The plant may differ from the planner's model (issue 17: a real table never is it).
        plant = plant_of(config, options, "sim: drive option ")
        self._axes = SimAxes(plant, np.rint(start_mm / self.pulse_mm).astype(np.int64))
        self._switches = SimSwitches(self.n_axes, options, self._axes.actual_mm.copy(), "sim")
        self._homing_run: SimAxesHoming | None = None
        self._homing_done = threading.Event()
        self._fault_axis: int | None = None  # the axis of the last injected drive fault
        self._lock = threading.RLock()
        self._status = CardStatus.OK
        self._messages: list[str] = []
        self._streaming = False  # frames since the last end-of-stream (an empty FIFO is an error)
        self._written = 0  # frames accepted since open (sequence numbers)
        self.frame_outputs = FrameOutputQueue()  # M62's, each set as its frame is clocked
        self._discarded = np.zeros(self.n_axes, dtype=np.int64)
        self._trace: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._comm_ok = True
        self._estop_file = options.get("estop_input_file")
        self._estop_tripped = False  # the in-process e-stop input (test hook)
        self._fault_file = options.get("drive_fault_file")
        # G38: the probe is in contact while the table's true position is inside this box
        self._workpiece = workpiece_option(options.get("probe_workpiece_mm"), "sim: drive option")
        self._limit_file = options.get("limit_input_file")
        self._limit_tripped: tuple[int, int] | None = None  # the in-process input (test hook)
        self._outputs_file = options.get("outputs_file")
        self.output_image = OutputImage()  # what the card's outputs hold
        self.spindle = SimSpindle(config.io.spindle, spinup_option(
            options.get("spindle_spinup_s"), "sim: drive option"), self._card_s)
        self._clocked = 0  # every period since open, idle ones included (frames_clocked)
        self._t0_s = 0.0  # real time: the start of period 0 (periods are due from it)
        self._quiet = 0  # periods clocked in a row with nothing to do (see _sleep_at_rest)
        self._resting = False  # asleep at rest: the idle periods are skipped, not clocked
        self._catching_up = False
        self._wake_frames = max(1, round(WAKE_EVERY_S / self.period_s))
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake = threading.Event()  # work for a clock asleep at rest (see _clock_thread)

    # -- hooks ----------------------------------------------------------------------------
    def _open(self) -> None:
        self._comm_ok = True  # a port opened again is a fresh link
        if self.realtime:
            self._stop.clear()
            # Period 0 is due at open, or (opened again) the periods go on from here.
            self._t0_s = time.monotonic() - self._clocked * self.period_s
            self._thread = threading.Thread(target=self._clock_thread, name="simcard",
                                            daemon=True)
            self._thread.start()

    def _close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self._thread = None

    def _recall_frames(self, n: int, keep: int) -> int:
        with self._lock:
            self._catch_up(ahead=False)
            got = self._fifo.recall(n, keep) if not self._status.halted else 0
            self._written -= got
            self.frame_outputs.taken_back(self._written)
            return got

    def _send_frames(self, frames: np.ndarray, end_of_stream: bool) -> None:
        self._check_comm()
        self._wake.set()
        if frames.size and int(np.abs(frames).max()) > self.max_pulses:
            with self._lock:
                self._catch_up(ahead=False)  # the fault latched at the time of the write
            self._latch(CardStatus.BAD_FRAME, f"bad frame: more than {self.max_pulses} "
                        "pulses in one sample")
            raise BadFrameError(self._fault_message())
        with self._lock:
            self._catch_up()
            room = self._fifo.capacity - len(self._fifo) - self.ahead_span()
            if (not frames.shape[0] and end_of_stream) or frames.shape[0] > room:
                self.take_back_ahead()  # its end marked, or its slots reached: as unclocked
            if self._status.halted:
                raise self._error()
            if not frames.shape[0]:
                # An end-of-stream with no frame ends the frames already queued (or executed).
                if end_of_stream and not self._fifo.mark_end():
                    self._streaming = False
                return
            self._fifo.push(frames, self._written, end_of_stream)
            self._written += frames.shape[0]
            self._streaming = True

    def _fifo_level(self) -> int:
        self._check_comm()
        with self._lock:
            self._catch_up()
            return self.queued_frames()

    def _fifo_capacity(self) -> int:
        return self._fifo.capacity

    def _read_feedback(self) -> Feedback:
        self._check_comm()
        with self._lock:
            self._catch_up()
            trace, self._trace = self._trace, []
        if not trace:
            empty = np.zeros((0, self.n_axes), dtype=np.int64)
            return Feedback(np.zeros(0, dtype=np.int64), empty, empty.copy())
        if len(trace) == 1:  # a cycle's rows, from one block
            return Feedback(*trace[0])
        return Feedback(*(np.concatenate(parts) for parts in zip(*trace, strict=True)))

    def _read_position(self) -> tuple[np.ndarray, np.ndarray]:
        self._check_comm()
        with self._lock:
            self._catch_up(ahead=False)
            return self._axes.commanded.copy(), self._axes.encoder(self._axes.actual_mm)

    def _read_status(self) -> CardStatus:
        self._check_comm()
        with self._lock:
            self._catch_up()
        if self._fault_file is not None and CardStatus.FAULT not in self._status \
                and os.path.exists(str(self._fault_file)):
            self.inject_drive_fault(0)  # the test's fault, from another process
        with self._lock:
            return self._status

    def _fault_message(self) -> str:
        with self._lock:
            return "; ".join(self._messages)

    def _reset(self) -> None:
        self._check_comm()
        with self._lock:
            self._catch_up(ahead=False)
            self._discarded += self._fifo.clear()
            self.frame_outputs.waiting.clear()
            self._status = CardStatus.OK
            self._messages = []
            self._streaming = False
        self._wake.set()

    def _disable(self) -> None:
        """The axes released: queued frames dropped, none taken until reset (they stand
        where the stop left them: the simulated table has no load to pull it away)."""
        self._check_comm()
        with self._lock:
            self._catch_up(ahead=False)
            self._discarded += self._fifo.clear()
            self.frame_outputs.waiting.clear()
            self._streaming = False

    def _estop_input(self) -> bool:
        return self._estop_tripped or (self._estop_file is not None
                                       and os.path.exists(str(self._estop_file)))

    def _probe_input(self) -> bool | None:
        if self._workpiece is None:
            return None
        return self._workpiece.contact(self.true_position_mm())

    def trip_estop_input(self, tripped: bool = True) -> None:
        """The e-stop input opens (True) or closes again (test hook)."""
        self._estop_tripped = tripped

    def _limit_input(self) -> str | None:
        names = self.config.axis_names
        tripped = self._limit_tripped or limit_tripped(self._limit_file, names)
        return None if tripped is None else switch_name(names[tripped[0]], tripped[1])

    def trip_limit_input(self, axis: int | None, direction: int = 1) -> None:
        """A limit switch trips (axis index, +1 or -1) or none is (None) (test hook)."""
        self._limit_tripped = None if axis is None else (axis, direction)

    def at_speed_input(self) -> bool:
        return self.spindle.at_speed()

    def _card_s(self) -> float:  # the card's clock: wall time, or the periods clocked
        return time.monotonic() if self.realtime else self._clocked * self.period_s

    def _write_outputs(self, image: OutputImage) -> None:
        self._check_comm()
        # (No catch-up here: clocking sets the outputs due at their frames through
        # set_outputs, which would land inside the write that called this one.)
        self.output_image = image
        self.spindle.written(image.bits, image.analog)
        record_outputs(self._outputs_file, image.bits, image.analog)

    # -- homing ---------------------------------------------------------------------------
    def _stream_active(self) -> bool:
        with self._lock:
            self._catch_up()
            return self._streaming or self.queued_frames() > 0

    def _homed(self) -> tuple[bool, ...]:
        return tuple(h or self._switches.homed_at_start for h in super()._homed())

    def _home(self, axes: tuple[int, ...], timeout_s: float) -> None:
        plans = {i: plan_for(self.config, i) for i in axes}
        run = self._switches.homing(self._axes, plans, self.period_s, self.config.axis_names)
        self._homing_done.clear()
        with self._lock:
            self._catch_up(ahead=False)  # the periods before it are idle ones
            self._homing_run = run
        self._wake.set()
        if self.realtime:
            deadline_s = time.monotonic() + timeout_s
            while not self._homing_done.wait(0.02):
                reason = self.homing_aborted()
                if reason or time.monotonic() > deadline_s:
                    with self._lock:
                        run.halt(reason or timeout_message(timeout_s))
                    self._homing_done.wait(5.0)
                    break
        else:
            limit = int(np.ceil(timeout_s / self.period_s))
            while not run.finished and run.samples < limit + 100_000:
                reason = self.homing_aborted()
                if run.samples >= limit or reason:
                    run.halt(reason or timeout_message(timeout_s))
                self.advance(256)
        with self._lock:
            self._homing_run = None
        if not run.finished or run.error:
            name = run.failed_name or self.config.axes[axes[0]].name
            raise HomingError(f"{name.upper()} axis homing failed: {run.error or 'no end'}",
                              name)

    def _clock_homing(self, n: int) -> int:
        """Homing samples instead of FIFO frames (called with the lock held)."""
        run = self._homing_run
        assert run is not None
        if self._status.halted:
            run.halt(f"drive fault during homing: {self._fault_message()}", at_once=True,
                     axis=self._fault_axis)
        used = run.step(n)
        if run.finished:
            self._homing_run = None
            self._homing_done.set()
        return used

    def true_position_mm(self) -> np.ndarray:
        """Where the simulated table really is (test hook): once homed, counts x pulse_mm."""
        with self._lock:
            self._catch_up(ahead=False)
            return self._axes.actual_mm + self._switches.offset_mm

    # -- clocking -------------------------------------------------------------------------
    def advance(self, n_frames: int) -> None:
        """Virtual time: clock n periods now (real-time mode clocks from its own thread)."""
        with self._lock:
            self._clock(n_frames)

    @property
    def frames_clocked(self) -> int:
        """Every period clocked since open, idle ones included (real time: up to now)."""
        with self._lock:
            self._catch_up()
            return self._clocked

    @frames_clocked.setter
    def frames_clocked(self, value: int) -> None:
        self._clocked = value

    def _catch_up(self, ahead: bool = True) -> None:
        """Real time: clock every period due by now (the lock held): the rows of the block
        stepped ahead first (drivers/sim/ahead.py), then from the FIFO; then the next block
        ahead, or (ahead=False, for what changes the card) none, taken back. At rest the
        periods are skipped (see _sleep_at_rest) while nothing is to be done: whatever gives
        the clock work (a write, a homing, an injected lag) calls this first, so the periods
        before it were idle ones."""
        if self._thread is None or self._catching_up:
            return  # (an output set as its frame is clocked is a call too)
        due = int((time.monotonic() - self._t0_s) / self.period_s) - self._clocked
        released = self.release_ahead(due)
        if released:
            due, self._quiet = due - released, 0
        if due > 0:
            self._clock_due(due)
        if ahead:
            self.clock_ahead()
        else:
            self.take_back_ahead()

    def _clock_due(self, due: int) -> None:
        busy = self._busy()
        if self._resting and not busy:
            self._clocked += due
            return
        self._resting = False
        self._catching_up = True
        try:
            self._clock(due)
        finally:
            self._catching_up = False
        self._quiet = 0 if busy else self._quiet + due

    def _clock_thread(self) -> None:
        """Clocks what fell due every few periods (every period while homing or while an
        output waits for its frame: their effects are seen from outside) and sleeps at rest."""
        while not self._stop.is_set():
            with self._lock:
                self._catch_up()
                per_period = self._homing_run is not None or self.frame_outputs.waiting
                every = 1 if per_period else self._wake_frames
                rest = self._quiet >= self._rest_frames
            if rest:
                self._sleep_at_rest()
                continue
            next_s = self._t0_s + (self._clocked + every) * self.period_s
            time.sleep(max(0.0, next_s - time.monotonic()))

    def _busy(self) -> bool:
        """Anything for the clock to do: frames, a stream, a homing, an injected lag ramping."""
        lag = self._axes
        return (self._streaming or self.queued_frames() > 0 or self._homing_run is not None
                or bool(np.any(lag.extra_lag_mm < lag.lag_target_mm)))

    def _sleep_at_rest(self) -> None:
        """An idle cncd costs no CPU: a table at rest for REST_AFTER_S stays at rest (its servo
        has settled to far below a pulse), so the clock sleeps until a write, a homing, a reset
        or an injection wakes it, and skips the idle periods instead of stepping the servo
        through them with zero velocity."""
        self._wake.clear()  # before the check: a wake-up after it is not lost
        with self._lock:
            if self._busy():
                self._quiet = 0
                return
            self._resting = True
        self._wake.wait()
        with self._lock:
            self._catch_up()  # the idle periods skipped
            self._resting = False
            self._quiet = 0

    def _clock(self, n: int) -> None:
        if self._homing_run is not None:
            used = self._clock_homing(n)
            self._clocked += used
            n -= used
        frames = np.zeros((0, self.n_axes), dtype=np.int64)
        seq = np.zeros(0, dtype=np.int64)
        if not self._status.halted:
            frames, seq, eos = self._fifo.pop(n)
            if eos.any():
                self._streaming = bool(len(self._fifo)) or not eos[-1]
            if len(frames) < n and self._streaming:
                self._latch(CardStatus.UNDERRUN, "card FIFO underrun: frames ran out "
                            f"mid-program after frame {self._written - 1}; card stopped")
        # Idle or halted periods still run the servo with zero velocity (motors hold).
        idle = np.zeros((n - len(frames), self.n_axes), dtype=np.int64)
        cmd, enc = self._axes.step(np.concatenate([frames, idle]))
        if len(frames):
            self._trace.append((seq, cmd[: len(frames)], enc[: len(frames)]))
            self.frame_outputs.due(int(seq[-1]), self.set_outputs)
        self._clocked += n

    def schedule_outputs(self, changes: Sequence[OutputChange], frames_back: int) -> None:
        with self._lock:
            self._catch_up(ahead=False)
            self.frame_outputs.waiting.append((self._written - 1 - frames_back, changes))

    def _latch(self, flag: CardStatus, message: str) -> None:
        with self._lock:
            self.take_back_ahead()  # a halted card clocks no frame after it
            self._status |= flag
            self._messages.append(message)

    def _error(self) -> DriveError:
        from drivers.errors import DriveFaultError, UnderrunError
        kinds = ((CardStatus.FAULT, DriveFaultError), (CardStatus.UNDERRUN, UnderrunError),
                 (CardStatus.BAD_FRAME, BadFrameError))
        cls = next((c for flag, c in kinds if flag in self._status), DriveError)
        return cls(self._fault_message())

    def _check_comm(self) -> None:
        if not self._comm_ok:
            raise LostCommunicationError("lost communication with the sim card "
                                         "(no report from the board)")

    # -- accounting and fault injection (test hooks) --------------------------------------
    @property
    def discarded_counts(self) -> np.ndarray:
        """Pulses accepted but never executed (dropped by reset or an injected underrun)."""
        with self._lock:
            self._catch_up()
            return self._discarded.copy()

    def inject_drive_fault(self, axis: int, code: int = 0x2310) -> None:
        """Amplifier fault on one axis: that axis coasts (frozen), the card stops."""
        self._wake.set()
        with self._lock:
            self._catch_up(ahead=False)
            self._axes.freeze(axis)
            self._fault_axis = axis
            name = self.config.axes[axis].name.upper()
            self._latch(CardStatus.FAULT, f"{name} axis drive fault 0x{code:04X}")

    def inject_lag(self, axis: int, lag_mm: float, ramp_frames: int = 20) -> None:
        """Mechanical drag: the encoder reads a further lag_mm below the servo model (ramped in)."""
        self._wake.set()
        with self._lock:
            self._catch_up(ahead=False)
            self._axes.add_lag(axis, abs(lag_mm), ramp_frames)

    def inject_stall(self, axis: int) -> None:
        """The axis stops moving while the card keeps stepping it."""
        self._wake.set()
        with self._lock:
            self._catch_up(ahead=False)
            self._axes.freeze(axis)

    def inject_underrun(self) -> None:
        """Lose every queued frame (as if the host's frames never arrived)."""
        self._wake.set()
        with self._lock:
            self._catch_up(ahead=False)
            self._discarded += self._fifo.clear()

    def inject_lost_comm(self) -> None:
        """The board stops answering; it keeps clocking what it holds (then underruns)."""
        with self._lock:
            self._catch_up()
        self._comm_ok = False

    def restore_comm(self) -> None:
        self._comm_ok = True


def _option(options: dict[str, Any], key: str, default: float, lo: float, hi: float) -> float:
    """A numeric drive option within [lo, hi], or a DriveError naming it."""
    value = options.get(key, default)
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise DriveError(f"sim: drive option {key}: {value!r} is not a number") from None
    if not lo <= number <= hi:
        raise DriveError(f"sim: drive option {key}: {value!r} is not in [{lo:g}, {hi:g}]")
    return number
