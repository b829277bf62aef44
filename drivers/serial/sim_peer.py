"""Simulated serial pulse card on a pseudo-terminal: frame FIFO, Table II axes, fault injection."""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections.abc import Callable
from typing import Any

import numpy as np

from controller.config import MachineConfig
from controller.errors import DriveError
from controller.servo.plant_option import PLANT_OPTIONS
from drivers.homing import HomingPlan
from drivers.io_peer import limit_tripped, record_outputs, workpiece_option
from drivers.serial import protocol as p
from drivers.sim.axes import SimAxes, plant_of
from drivers.sim.fifo import FrameFifo
from drivers.sim.homing import SimAxesHoming
from drivers.sim.spindle import SimSpindle, spinup_option
from drivers.sim.switches import SWITCH_OPTIONS, SimSwitches

# Option -> default. Times marked "after" count from the first sample frame received.
PEER_OPTIONS: dict[str, Any] = {
    "fifo_frames": 256,
    "status_period_s": 0.010,
    "max_pulses_per_frame": 32767,
    "start_mm": None,
    "drive_fault_after_frames": None,  # axis amplifier fault after N executed samples
    "drive_fault_axis": 0,
    "drive_fault_code": 0x2310,
    "lag_mm": None,  # extra encoder lag (mechanical drag) after lag_after_frames
    "lag_after_frames": 200,
    "lag_axis": 0,
    "silent_after_s": None,  # stop sending anything (status frames, replies)
    "corrupt_status_after_s": None,  # every status frame sent with a bad CRC
    "corrupt_rx_after_frames": None,  # line noise: the next received bytes fail their CRC
    "drop_frame_after_frames": None,  # lose one received sample (a sequence gap follows)
    # homing (drivers/sim/switches.py): lists per axis, true frame of the simulated table
    "true_start_mm": None,  # where the table really is at power-up (default: start_mm)
    "home_switch_mm": None,  # each axis's switch (default: where HOME says home is; null: none)
    "index_pitch_mm": 1.0,  # encoder index marks at multiples of this
    "homing_fault_after_s": None,  # drive_fault_axis faults this long into a HOME
    "estop_input_file": None,  # a path: the e-stop input is open while this file exists
    "probe_workpiece_mm": None,  # x0,y0,z0,x1,y1,z1: the probe is in contact inside this box
    "limit_input_file": None,  # a path: the limit switch it names ("x+") is open while it exists
    "outputs_file": None,  # a path: the outputs as JSON, written on every OUTPUTS frame
    "spindle_spinup_s": None,  # the at-speed input (io AT_SPEED) this long after a start; never
} | dict.fromkeys(PLANT_OPTIONS)  # each axis's own loop, mismatch (controller/servo/plant_option)
LIST_OPTIONS = ("start_mm", "true_start_mm", "home_switch_mm", "probe_workpiece_mm")
TEXT_OPTIONS = ("estop_input_file", "limit_input_file", "outputs_file")
SPINUP = "spindle_spinup_s"  # seconds or "never" (drivers/sim/spindle.py checks it)


def check_options(options: dict[str, Any]) -> dict[str, Any]:
    """Options merged over the defaults; an unknown one is a DriveError naming it."""
    unknown = sorted(set(options) - set(PEER_OPTIONS))
    if unknown:
        raise DriveError(f"serial simdrive: unknown option {unknown[0]!r} "
                         f"(known: {', '.join(sorted(PEER_OPTIONS))})")
    merged = PEER_OPTIONS | options
    for key, value in merged.items():
        if key in LIST_OPTIONS or key in PLANT_OPTIONS or value is None or key == SPINUP:
            continue
        if key in TEXT_OPTIONS:
            if not isinstance(value, str) or not value:
                raise DriveError(f"serial simdrive: option {key!r} must be a path, "
                                 f"got {value!r}")
            continue
        if isinstance(value, bool) or not isinstance(value, int | float) or value < 0:
            raise DriveError(f"serial simdrive: option {key!r} must be a number >= 0, "
                             f"got {value!r}")
    return merged


class PeerCard:
    """The card's logic, clocked by run(); frames in through handle_bytes(), reports out
    through `send` (bytes)."""

    def __init__(self, config: MachineConfig, options: dict[str, Any],
                 send: Callable[[bytes], None]) -> None:
        self.opt = check_options(options)
        self.send_raw = send
        self.n = len(config.axes)
        self.period_s = config.sample_period_s
        self.status_period_s = float(self.opt["status_period_s"])
        self.max_pulses = int(self.opt["max_pulses_per_frame"])
        pulse_mm = np.array([a.pulse_mm for a in config.axes])
        start = self.opt["start_mm"] if self.opt["start_mm"] is not None else [0.0] * self.n
        self.fifo = FrameFifo(int(self.opt["fifo_frames"]), self.n)
        self.axes = SimAxes(peer_plant(config, self.opt),
                            np.rint(np.asarray(start, float) / pulse_mm).astype(np.int64))
        self.axis_names = config.axis_names
        self.switches = SimSwitches(self.n, {k: v for k, v in self.opt.items()
                                             if k in SWITCH_OPTIONS and v is not None},
                                    self.axes.actual_mm.copy(), "serial simdrive")
        self.homing: SimAxesHoming | None = None
        self.workpiece = workpiece_option(self.opt["probe_workpiece_mm"], "serial simdrive: option")
        self.home_token = 0
        self.home_started_s = 0.0
        self.home_aborted = False
        self.decoder = p.Decoder(p.HOST_SYNC)
        self.latched = 0
        self.disabled = False  # amplifiers off: a DISABLE frame, until a RESET
        self.fault_axis = self.fault_code = 0
        self.expect_seq: int | None = None  # None after power-up or reset: any seq is accepted
        self.rx_seq = self.exec_seq = p.SEQ_MOD - 1
        self.streaming = False
        self.executed_last_tick = False
        self.prev_cmd = self.cur_cmd = self.axes.commanded.copy()
        self.prev_enc = self.cur_enc = self.axes.encoder(self.axes.actual_mm)
        self.samples_rx = 0
        self.samples_exec = 0
        self.first_rx_s: float | None = None
        self.injected: set[str] = set()
        self.outputs = p.Outputs(0, 0)  # the digital outputs and analog channels
        self.spindle = SimSpindle(config.io.spindle, spinup_option(
            self.opt[SPINUP], "serial simdrive: option"), lambda: self.ticks * self.period_s)
        self.t0_s = time.monotonic()
        self.ticks = 0

    # -- receiving --------------------------------------------------------------------------
    def handle_bytes(self, data: bytes) -> None:
        after = self.opt["corrupt_rx_after_frames"]
        if after is not None and self.samples_rx >= after and "rx" not in self.injected and data:
            self.injected.add("rx")
            data = data[:-1] + bytes([data[-1] ^ 0xFF])  # the last CRC byte of this chunk
        errors = self.decoder.crc_errors
        frames = self.decoder.feed(data)
        if self.decoder.crc_errors > errors:
            self.latched |= p.ST_BAD_FRAME
        for frame in frames:
            self.handle(frame)

    def handle(self, frame: p.Frame) -> None:
        if isinstance(frame, p.Sample):
            self._sample(frame)
        elif isinstance(frame, p.Home):
            self._home(frame)
        elif isinstance(frame, p.Reset):
            if self.homing is not None:  # abort: the axes decelerate, no HOME_FAILED
                self.homing.halt("aborted by a RESET")
                self.home_aborted = True
            self.fifo.clear()
            self.latched = 0
            self.fault_axis = self.fault_code = 0
            self.expect_seq = None
            self.streaming = False
            self.disabled = self.disabled and self.estop_input()  # the input must be closed
            self.send_status(frame.token)
        elif isinstance(frame, p.Disable):
            if self.homing is not None:
                self.homing.halt("aborted by a DISABLE")
                self.home_aborted = True
            self.fifo.clear()
            self.expect_seq = None
            self.streaming = False
            self.disabled = True
            self.send_status(frame.token)
        elif isinstance(frame, p.StatusRequest):
            self.send_status(frame.token)
        elif isinstance(frame, p.Outputs):
            self.outputs = frame  # the outputs hold these from now (the host sets them safe)
            self.spindle.written(frame.bits, frame.analog)
            record_outputs(self.opt["outputs_file"], frame.bits, frame.analog)
            self.send_status(frame.token)
        elif isinstance(frame, p.End):
            if not self.fifo.mark_end():
                self.streaming = False
        elif isinstance(frame, p.Recall):
            self._recall(frame)
            self.send_status(frame.token)

    def _sample(self, s: p.Sample) -> None:
        self.samples_rx += 1
        if self.first_rx_s is None:
            self.first_rx_s = time.monotonic()
        drop = self.opt["drop_frame_after_frames"]
        if drop is not None and self.samples_rx == drop + 1:
            return  # lost on the wire
        if self.latched & p.ST_LATCHED or self.disabled:
            return  # halted, or the amplifiers off: nothing is queued until a reset
        if self.expect_seq is not None and s.seq != self.expect_seq:
            self.latched |= p.ST_SEQ_GAP
            return
        if len(s.counts) != self.n or max(abs(c) for c in s.counts) > self.max_pulses \
                or len(self.fifo) >= self.fifo.capacity:
            self.latched |= p.ST_BAD_FRAME
            return
        self.fifo.push(np.asarray([s.counts], dtype=np.int64), s.seq, s.end_of_stream)
        self.rx_seq = s.seq
        self.expect_seq = (s.seq + 1) % p.SEQ_MOD
        self.streaming = True

    def _recall(self, r: p.Recall) -> None:
        """Take back the samples from r.first_seq through the last received, all or none
        (docs/serial-protocol.md, RECALL); the reply's rx_seq says which happened."""
        if self.latched & p.ST_LATCHED or self.disabled or self.expect_seq is None:
            return
        n = (self.rx_seq - r.first_seq + 1) % p.SEQ_MOD
        if 0 < n <= len(self.fifo) and self.fifo.recall(n, r.keep) == n:
            self.rx_seq = (r.first_seq - 1) % p.SEQ_MOD
            self.expect_seq = r.first_seq % p.SEQ_MOD

    # -- homing -----------------------------------------------------------------------------
    def _home(self, h: p.Home) -> None:
        """Start a homing sequence (docs/serial-protocol.md, HOME) and answer at once."""
        self.latched &= ~p.ST_HOME_FAILED
        axes = [i for i in range(self.n) if h.mask >> i & 1]
        busy = self.homing is not None or self.latched & p.ST_LATCHED or len(self.fifo) \
            or self.streaming
        bad = len(h.axes) != self.n or not axes or any(
            h.axes[i].direction not in (-1, 1) or h.axes[i].search_pps <= 0
            or not 0 < h.axes[i].latch_pps <= h.axes[i].search_pps or h.axes[i].accel_pps2 <= 0
            for i in axes)
        if busy or bad:
            self._home_failed(axes[0] if axes else 0, p.HOME_BUSY if busy else p.HOME_BAD_REQUEST)
        else:
            pulse = self.axes.pulse_mm
            plans = {i: HomingPlan(
                axis=self.axis_names[i], direction=a.direction, search_mm_s=a.search_pps * pulse[i],
                latch_mm_s=a.latch_pps * pulse[i], accel_mm_s2=a.accel_pps2 * pulse[i],
                home_mm=a.home_pulses * pulse[i], final_mm=a.final_pulses * pulse[i],
                use_index=a.use_index, search_limit_mm=a.search_limit_pulses * pulse[i])
                for i, a in enumerate(h.axes) if i in axes}
            self.homing = self.switches.homing(self.axes, plans, self.period_s,
                                               self.axis_names)
            self.home_token, self.home_aborted = h.token, False
            self.home_started_s = time.monotonic()
        self.send_status(h.token)

    def _home_failed(self, axis: int, code: int) -> None:
        self.latched |= p.ST_HOME_FAILED
        if not self.latched & p.ST_DRIVE_FAULT:
            self.fault_axis, self.fault_code = axis, code

    def _clock_homing(self, n: int) -> int:
        """Homing samples instead of FIFO samples; the counters are reported as they go."""
        run = self.homing
        assert run is not None
        after = self.opt["homing_fault_after_s"]
        if after is not None and "home_fault" not in self.injected \
                and time.monotonic() - self.home_started_s >= float(after):
            self.injected.add("home_fault")
            self.fault_axis = int(self.opt["drive_fault_axis"])
            self.fault_code = int(self.opt["drive_fault_code"])
            self.axes.freeze(self.fault_axis)
            self.latched |= p.ST_DRIVE_FAULT
        if self.latched & p.ST_DRIVE_FAULT:
            run.halt("drive fault", at_once=True, axis=self.fault_axis)
        used = run.step(n)
        self.prev_cmd, self.prev_enc = self.cur_cmd, self.cur_enc
        self.cur_cmd = self.axes.commanded.copy()
        self.cur_enc = self.axes.encoder(self.axes.actual_mm)
        self.executed_last_tick = False
        if run.finished:
            self.homing = None
            if run.error and not self.home_aborted and not self.latched & p.ST_DRIVE_FAULT:
                code = p.HOME_NO_RELEASE if "release" in run.error else p.HOME_NOT_FOUND
                self._home_failed(run.failed_axis or 0, code)
            self.send_status(self.home_token)
        return used

    # -- clocking ---------------------------------------------------------------------------
    def clock(self, n: int) -> None:
        if self.homing is not None:
            used = self._clock_homing(n)
            self.ticks += used
            n -= used
            if not n:
                return
        frames = np.zeros((0, self.n), dtype=np.int64)
        seq = np.zeros(0, dtype=np.int64)
        if not self.latched & p.ST_LATCHED:
            frames, seq, eos = self.fifo.pop(n)
            if eos.any():
                self.streaming = bool(len(self.fifo)) or not eos[-1]
            if len(frames) < n and self.streaming:
                self.latched |= p.ST_UNDERRUN
        idle = np.zeros((n - len(frames), self.n), dtype=np.int64)
        cmd, enc = self.axes.step(np.concatenate([frames, idle]))
        if n >= 2:
            self.prev_cmd, self.prev_enc = cmd[-2], enc[-2]
        elif n == 1:
            self.prev_cmd, self.prev_enc = self.cur_cmd, self.cur_enc
        if n:
            self.cur_cmd, self.cur_enc = cmd[-1], enc[-1]
        self.executed_last_tick = len(frames) == n and n > 0
        if len(frames):
            self.exec_seq = int(seq[-1]) % p.SEQ_MOD
            self.samples_exec += len(frames)
        self.ticks += n
        self._inject_clocked()

    def _inject_clocked(self) -> None:
        after = self.opt["drive_fault_after_frames"]
        if after is not None and self.samples_exec >= after and "fault" not in self.injected:
            self.injected.add("fault")
            self.fault_axis = int(self.opt["drive_fault_axis"])
            self.fault_code = int(self.opt["drive_fault_code"])
            self.axes.freeze(self.fault_axis)
            self.latched |= p.ST_DRIVE_FAULT
        lag = self.opt["lag_mm"]
        if lag is not None and self.samples_exec >= int(self.opt["lag_after_frames"]) \
                and "lag" not in self.injected:
            self.injected.add("lag")
            self.axes.add_lag(int(self.opt["lag_axis"]), abs(float(lag)), 20)

    def _after(self, key: str) -> bool:
        after = self.opt[key]
        return (after is not None and self.first_rx_s is not None
                and time.monotonic() - self.first_rx_s >= float(after))

    def estop_input(self) -> bool:
        """The card's e-stop input: open (True) while the option's file exists."""
        path = self.opt["estop_input_file"]
        return path is not None and os.path.exists(path)

    def probe_input(self) -> bool:
        """The probe input: in contact while the table's true position is inside the work."""
        return self.workpiece is not None and self.workpiece.contact(
            self.axes.actual_mm + self.switches.offset_mm)

    def limit_io(self) -> int:
        """The io bit of the limit switch the option's file names, while it exists."""
        tripped = limit_tripped(self.opt["limit_input_file"], self.axis_names)
        return 0 if tripped is None else p.limit_bits(*tripped)

    def send_status(self, reply_to: int = 0) -> None:
        if self._after("silent_after_s"):
            return
        cur_cmd, cur_enc = self.cur_cmd, self.cur_enc
        status = p.Status(
            reply_to=reply_to, fifo_level=len(self.fifo), fifo_capacity=self.fifo.capacity,
            latched=self.latched | (p.ST_EXECUTED if self.executed_last_tick else 0)
            | (p.ST_HOMING if self.homing is not None else 0),
            fault_axis=self.fault_axis, fault_code=self.fault_code, rx_seq=self.rx_seq,
            exec_seq=self.exec_seq, commanded=tuple(int(c) for c in cur_cmd),
            encoder=tuple(int(e) for e in cur_enc),
            commanded_delta=tuple(int(c) for c in cur_cmd - self.prev_cmd),
            encoder_delta=tuple(int(e) for e in cur_enc - self.prev_enc),
            io=(p.IO_DISABLED if self.disabled else 0)
            | (p.IO_ESTOP_INPUT if self.estop_input() else 0) | self.limit_io()
            | (p.IO_PROBE_INPUT if self.probe_input() else 0)
            | (p.IO_AT_SPEED if self.spindle.at_speed() else 0))
        data = p.encode_status(status)
        if self._after("corrupt_status_after_s"):
            data = data[:-1] + bytes([data[-1] ^ 0xFF])
        self.send_raw(data)

    def run(self, read_fd: int, stop: threading.Event) -> None:
        """Serve until stop is set: one frame per T in wall-clock time (a late wake-up clocks
        every frame that fell due), a status frame every status period."""
        self.t0_s = time.monotonic()
        next_status_s = self.t0_s + self.status_period_s
        while not stop.is_set():
            now_s = time.monotonic()
            next_tick_s = self.t0_s + (self.ticks + 1) * self.period_s
            wait_s = max(0.0, min(next_tick_s, next_status_s) - now_s)
            ready, _, _ = select.select([read_fd], [], [], wait_s)
            if ready:
                try:
                    self.handle_bytes(os.read(read_fd, 4096))
                except BlockingIOError:
                    pass
            now_s = time.monotonic()
            due = int((now_s - self.t0_s) / self.period_s) - self.ticks
            if due > 0:
                self.clock(due)
            if now_s >= next_status_s:
                self.send_status()
                next_status_s = max(next_status_s + self.status_period_s, now_s)


def peer_plant(config: MachineConfig, opt: dict[str, Any]) -> MachineConfig:
    """The machine the card runs: its plant options given (not None) over the config's model."""
    given = {k: v for k, v in opt.items() if k in PLANT_OPTIONS and v is not None}
    return plant_of(config, given, "serial simdrive: option ")


def _try_realtime(priority: int = 70) -> None:
    """A card keeps time in hardware; the simulated one asks for SCHED_FIFO to come close (a
    starved card would look like a silent one). Without the privilege it runs as it is."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError):
        pass


def serve(config: MachineConfig, options: dict[str, Any], announce: Callable[[str], None],
          stop: threading.Event) -> None:
    """`cncctl simdrive serial`: the card on a new pty; announce(path) once it can be opened."""
    peer_plant(config, check_options(options))  # a bad plant is refused before the pty opens
    master_fd, slave_fd = os.openpty()
    try:
        tty.setraw(slave_fd)
        os.set_blocking(master_fd, False)

        def send(data: bytes) -> None:
            try:
                os.write(master_fd, data)
            except (BlockingIOError, OSError):
                pass  # nobody reading: the bytes are lost, as on a real UART

        card = PeerCard(config, options, send)
        _try_realtime()
        # The slave stays open here too, so the pty survives hosts closing and reopening it.
        announce(os.ttyname(slave_fd))
        card.run(master_fd, stop)
    finally:
        os.close(master_fd)
        os.close(slave_fd)
