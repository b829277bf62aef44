"""The `sim` backend: a simulated bit-pattern pulse card with a frame FIFO and servo axes."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from controller.config import MachineConfig
from controller.generator.dynamics.servo import mismatched_config
from drivers.base import CardStatus, Drive, Feedback
from drivers.errors import BadFrameError, DriveError, LostCommunicationError
from drivers.sim.axes import SimAxes
from drivers.sim.fifo import FrameFifo


class SimCard(Drive):
    """Frames are clocked one per sample period T, in wall-clock time or virtual time.

    Options: realtime (bool, default True), fifo_frames (256), max_pulses_per_frame (127,
    an int8 frame as in the prototype protocol), start_mm (list, machine position at power-up),
    plant_pole_pct and plant_gain_pct (0: a plant off the planner's model, see mismatched).
    Card rule (hostmot2 watchdog): an empty FIFO mid-program stops the card and latches
    UNDERRUN until reset(); an empty FIFO after an end-of-stream frame is simply idle.
    """

    OPTIONS = frozenset({"realtime", "fifo_frames", "max_pulses_per_frame", "start_mm",
                         "plant_pole_pct", "plant_gain_pct"})

    def __init__(self, config: MachineConfig, **options: Any) -> None:
        super().__init__(config, **options)
        self.period_s = config.sample_period_s
        self.realtime = bool(options.get("realtime", True))
        self.max_pulses = int(options.get("max_pulses_per_frame", 127))
        start_mm = np.asarray(options.get("start_mm", np.zeros(self.n_axes)), dtype=float)
        self._fifo = FrameFifo(int(options.get("fifo_frames", 256)), self.n_axes)
        # The plant may differ from the planner's model (issue 17: a real table never is it).
        plant = mismatched_config(config, float(options.get("plant_pole_pct", 0.0)),
                                  float(options.get("plant_gain_pct", 0.0)))
        self._axes = SimAxes(plant, np.rint(start_mm / self.pulse_mm).astype(np.int64))
        self._lock = threading.RLock()
        self._status = CardStatus.OK
        self._messages: list[str] = []
        self._streaming = False  # frames since the last end-of-stream (an empty FIFO is an error)
        self._written = 0  # frames accepted since open (sequence numbers)
        self._discarded = np.zeros(self.n_axes, dtype=np.int64)
        self._trace: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._comm_ok = True
        self.frames_clocked = 0  # every period since open, idle ones included
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    # -- hooks ----------------------------------------------------------------------------
    def _open(self) -> None:
        if self.realtime:
            self._stop.clear()
            self._thread = threading.Thread(target=self._clock_thread, name="simcard",
                                            daemon=True)
            self._thread.start()

    def _close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self._thread = None

    def _send_frames(self, frames: np.ndarray, end_of_stream: bool) -> None:
        self._check_comm()
        if frames.size and int(np.abs(frames).max()) > self.max_pulses:
            self._latch(CardStatus.BAD_FRAME, f"bad frame: more than {self.max_pulses} "
                        "pulses in one sample")
            raise BadFrameError(self._fault_message())
        with self._lock:
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
            return len(self._fifo)

    def _fifo_capacity(self) -> int:
        return self._fifo.capacity

    def _read_feedback(self) -> Feedback:
        self._check_comm()
        with self._lock:
            trace, self._trace = self._trace, []
        if not trace:
            empty = np.zeros((0, self.n_axes), dtype=np.int64)
            return Feedback(np.zeros(0, dtype=np.int64), empty, empty.copy())
        return Feedback(*(np.concatenate(parts) for parts in zip(*trace, strict=True)))

    def _read_position(self) -> tuple[np.ndarray, np.ndarray]:
        self._check_comm()
        with self._lock:
            return self._axes.commanded.copy(), self._axes.encoder(self._axes.actual_mm)

    def _read_status(self) -> CardStatus:
        self._check_comm()
        with self._lock:
            return self._status

    def _fault_message(self) -> str:
        with self._lock:
            return "; ".join(self._messages)

    def _reset(self) -> None:
        self._check_comm()
        with self._lock:
            self._discarded += self._fifo.clear()
            self._status = CardStatus.OK
            self._messages = []
            self._streaming = False

    # -- clocking -------------------------------------------------------------------------
    def advance(self, n_frames: int) -> None:
        """Virtual time: clock n periods now (real-time mode clocks from its own thread)."""
        with self._lock:
            self._clock(n_frames)

    def _clock_thread(self) -> None:
        t0 = time.monotonic()
        while not self._stop.is_set():
            due = int((time.monotonic() - t0) / self.period_s) - self.frames_clocked
            if due > 0:  # a late wake-up clocks every frame that fell due, as hardware would
                with self._lock:
                    self._clock(due)
            next_s = t0 + (self.frames_clocked + 1) * self.period_s
            time.sleep(max(0.0, next_s - time.monotonic()))

    def _clock(self, n: int) -> None:
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
        self.frames_clocked += n

    def _latch(self, flag: CardStatus, message: str) -> None:
        with self._lock:
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
            return self._discarded.copy()

    def inject_drive_fault(self, axis: int, code: int = 0x2310) -> None:
        """Amplifier fault on one axis: that axis coasts (frozen), the card stops."""
        with self._lock:
            self._axes.freeze(axis)
            name = self.config.axes[axis].name.upper()
            self._latch(CardStatus.FAULT, f"{name} axis drive fault 0x{code:04X}")

    def inject_lag(self, axis: int, lag_mm: float, ramp_frames: int = 20) -> None:
        """Mechanical drag: the encoder reads a further lag_mm below the servo model (ramped in)."""
        with self._lock:
            self._axes.add_lag(axis, abs(lag_mm), ramp_frames)

    def inject_stall(self, axis: int) -> None:
        """The axis stops moving while the card keeps stepping it."""
        with self._lock:
            self._axes.freeze(axis)

    def inject_underrun(self) -> None:
        """Lose every queued frame (as if the host's frames never arrived)."""
        with self._lock:
            self._discarded += self._fifo.clear()

    def inject_lost_comm(self) -> None:
        """The board stops answering; it keeps clocking what it holds (then underruns)."""
        self._comm_ok = False

    def restore_comm(self) -> None:
        self._comm_ok = True

