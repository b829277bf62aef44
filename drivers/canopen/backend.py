"""The `canopen` backend: CiA 402 drives in cyclic synchronous position mode over CANopen."""

from __future__ import annotations

import contextlib
import os
import time
from typing import Any

import numpy as np

from controller.config import MachineConfig
from controller.outputs import OutputImage
from drivers.at_speed_input import AtSpeedInput
from drivers.base import CardStatus, Drive, Feedback
from drivers.canopen import bringup, homing, machine_io
from drivers.canopen import cia402 as c
from drivers.canopen.link import Link
from drivers.canopen.options import CanopenOptions, parse_options
from drivers.errors import (
    BadFrameError,
    DriveError,
    DriveFaultError,
    LostCommunicationError,
    UnderrunError,
)
from drivers.port_lock import device_key
from drivers.probe_latch import ProbeLatch

CLOSE_CONFIRM_S = 0.2  # wait this long for the drives to confirm the shutdown at close


class CanopenDrive(Drive, ProbeLatch, AtSpeedInput):
    """One BaseNode402 per axis; the host keeps the frame FIFO and clocks it out by SYNC.

    Each sample period T the cycle thread pops one frame (the sim card's rule: an empty FIFO
    mid-program latches UNDERRUN and quick-stops; after end-of-stream it is idle), adds it to
    the step counter, sends every drive its absolute target in RPDO1 (counts = pulses x
    pulse_mm x counts_per_mm) and then SYNC. TPDO1 (statusword, position actual) come back as
    feedback rows. Options: see drivers/canopen/options.py and docs/canopen.md.
    """

    def __init__(self, config: MachineConfig, **options: Any) -> None:
        super().__init__(config, **options)
        self.o: CanopenOptions = parse_options(config, options)
        self.period_s = config.sample_period_s
        c.period_code(self.period_s)  # a period the drives cannot be told is refused now
        self.axes = config.axis_names
        self._network: Any = None
        self._nodes: list[Any] = []
        self._link: Link | None = None
        self.bringup_s = 0.0
        self._last_stats: dict[str, float | int] = {}
        self._last_rtt_ms = np.zeros(0)
        self._io_written: OutputImage | None = None  # what the io_node holds, as written
        self._io_written_link: Link | None = None  # ... over this link (a new link: unknown)
        self._probe_toward = True  # the edge the touch probes were last armed for

    # -- open / close ---------------------------------------------------------------------
    def _lock_key(self) -> str:
        channel = self.o.channel
        if os.sep in channel:  # an adapter's device (slcan): one port, by whatever name
            channel = device_key(channel)
        return f"can-{self.o.interface}-{channel}"

    def _open(self) -> None:
        t0_s = time.monotonic()
        self._network = bringup.connect(self.o)
        try:
            self._nodes = bringup.add_nodes(self._network, self.o)
            positions = []
            for node, axis, cpm in zip(self._nodes, self.axes, self.o.counts_per_mm,
                                       strict=True):
                bringup.configure(node, axis, self.o, cpm, self.period_s)
                positions.append(bringup.sdo_read(node, axis, c.POSITION_ACTUAL, None,
                                                  "position actual"))
            self._link = Link(self._network, self._nodes, self.axes, self.o, self.period_s,
                              self.pulse_mm)
            self._link.rebase(positions)
            self._link.start()
            for node, axis in zip(self._nodes, self.axes, strict=True):
                bringup.enable(node, axis)
            self._enabled_since_bringup()
        except BaseException:
            self._shutdown()
            raise
        self.bringup_s = time.monotonic() - t0_s

    def _enabled_since_bringup(self) -> None:
        link = self._require_link()
        with link.lock:
            link.last_hb_s = [time.monotonic()] * link.n
            link.last_tpdo_cycle = [link.cycle_no] * link.n
            link.supervising = True

    def _close(self) -> None:
        self._shutdown()

    def _shutdown(self) -> None:
        """Leave every drive disabled (READY TO SWITCH ON), stop consuming our heartbeat,
        PRE-OPERATIONAL, then stop SYNC and close the adapter. Best effort when the bus is
        gone: a drive that cannot be told faults on its own heartbeat consumer (0x6007)."""
        link = self._link
        if link is not None:
            with link.lock:
                link.supervising = False
            self._last_stats = link.stats()
            with link.lock:
                self._last_rtt_ms = np.array(link.rtt_s) * 1e3
            for node, sw in zip(self._nodes, link.statusword, strict=True):
                with contextlib.suppress(Exception):  # 8: READY TO SWITCH ON; 12: DISABLED
                    node.controlword = c.CW_SHUTDOWN if c.state_of(sw) == "OPERATION ENABLED" \
                        else c.CW_DISABLE_VOLTAGE
            deadline_s = time.monotonic() + CLOSE_CONFIRM_S
            while time.monotonic() < deadline_s and link.cycle_no and any(
                    c.state_of(sw) in ("OPERATION ENABLED", "QUICK STOP ACTIVE")
                    for sw in link.statusword):
                time.sleep(self.period_s)
            comm_ok = CardStatus.LOST_COMM not in link.status
            if comm_ok:
                for node in self._nodes:
                    with contextlib.suppress(Exception):
                        node.sdo[c.CONSUMER_HEARTBEAT][1].raw = 0
                        node.nmt.state = "PRE-OPERATIONAL"
            link.stop()
        if self._network is not None:
            with contextlib.suppress(Exception):
                self._network.disconnect()
        self._network, self._link = None, None

    def _require_link(self) -> Link:
        if self._link is None:
            raise DriveError("canopen drive is not open")
        return self._link

    # -- frames ---------------------------------------------------------------------------
    def _send_frames(self, frames: np.ndarray, end_of_stream: bool) -> None:
        link = self._check_comm()
        with link.lock:
            if link.status.halted:
                raise self._error(link)
            if not frames.shape[0]:
                if end_of_stream and not link.fifo.mark_end():
                    link.streaming = False
                return
            try:
                link.fifo.push(frames, link.written, end_of_stream)
            except BadFrameError as exc:
                link.latch(CardStatus.BAD_FRAME, str(exc))
                raise
            link.written += frames.shape[0]
            link.streaming = True

    def _recall_frames(self, n: int, keep: int) -> int:
        """The FIFO is host-side (the SYNC thread streams it): frames not yet sent to the
        drives can be taken back."""
        link = self._check_comm()
        with link.lock:
            got = link.fifo.recall(n, keep) if not link.status.halted else 0
            link.written -= got
            return got

    def _fifo_level(self) -> int:
        link = self._check_comm()
        with link.lock:
            return len(link.fifo)

    def _fifo_capacity(self) -> int:
        return self.o.fifo_frames

    def _read_feedback(self) -> Feedback:
        link = self._check_comm()
        trace = link.take_trace()
        if trace is None:
            empty = np.zeros((0, self.n_axes), dtype=np.int64)
            return Feedback(np.zeros(0, dtype=np.int64), empty, empty.copy())
        return Feedback(*trace)

    def _read_position(self) -> tuple[np.ndarray, np.ndarray]:
        link = self._check_comm()
        with link.lock:
            return link.cmd.copy(), link.enc.copy()

    def _read_status(self) -> CardStatus:
        link = self._check_comm()
        with link.lock:
            return link.status

    def _fault_message(self) -> str:
        link = self._link
        if link is None:
            return ""
        with link.lock:
            return "; ".join(link.messages)

    def _check_comm(self) -> Link:
        link = self._require_link()
        with link.lock:
            if CardStatus.LOST_COMM in link.status:
                raise LostCommunicationError("; ".join(link.messages))
        return link

    def _error(self, link: Link) -> DriveError:
        kinds = ((CardStatus.FAULT, DriveFaultError), (CardStatus.FOLLOWING_ERROR,
                 DriveFaultError), (CardStatus.UNDERRUN, UnderrunError),
                 (CardStatus.BAD_FRAME, BadFrameError))
        cls = next((k for flag, k in kinds if flag in link.status), DriveError)
        return cls("; ".join(link.messages))

    # -- homing ---------------------------------------------------------------------------
    def _stream_active(self) -> bool:
        link = self._check_comm()
        with link.lock:
            return link.streaming or len(link.fifo) > 0

    def _home(self, axes: tuple[int, ...], timeout_s: float) -> None:
        homing.home(self, axes, timeout_s)

    def _homed(self) -> tuple[bool, ...]:
        """Host-side flags (a drive back in CSP no longer shows bit 12), lost when a drive
        reboots (its boot-up message: its position counter starts again)."""
        link = self._link
        rebooted = link.rebooted if link is not None else [True] * self.n_axes
        return tuple(h and not r for h, r in zip(super()._homed(), rebooted, strict=True))

    # -- reset ----------------------------------------------------------------------------
    def _reset(self) -> None:
        """Clear the latched flags, drop queued frames, fault-reset and re-enable the drives
        with the target at their actual position (bumpless)."""
        link = self._require_link()
        with link.lock:
            link.supervising = False
            link.discarded += link.fifo.clear()
            link.streaming = False
            link.status, link.messages = CardStatus.OK, []
            link.emcy_seen = [False] * link.n
            link.lost = [False] * link.n
        try:
            for node, axis in zip(self._nodes, self.axes, strict=True):
                state = c.state_of(bringup.wait_statusword(node, axis))
                if state == "FAULT":
                    bringup.fault_reset(node, axis)
                elif state == "OPERATION ENABLED":
                    node.controlword = c.CW_QUICK_STOP
                    bringup.wait_statusword(node, axis)
            bringup.wait_statusword(self._nodes[0], self.axes[0])
            with link.lock:
                link.rebase(list(link.counts))
            bringup.wait_statusword(self._nodes[0], self.axes[0])
            for node, axis in zip(self._nodes, self.axes, strict=True):
                bringup.enable(node, axis)
        except DriveError as exc:
            link.latch(CardStatus.FAULT, f"reset failed: {exc}")
            raise
        with link.lock:
            link.quick_stopped = False
        self._enabled_since_bringup()

    # -- e-stop ---------------------------------------------------------------------------
    def _disable(self) -> None:
        """Quick stop, then disable voltage (CiA 402 transitions 11 and 12): every drive
        ends in SWITCH ON DISABLED, the power stage off; reset() walks them back to
        OPERATION ENABLED. Supervision pauses: leaving OPERATION ENABLED is asked for."""
        link = self._check_comm()
        with link.lock:
            link.supervising = False
            link.discarded += link.fifo.clear()
            link.streaming = False
            link.quick_stopped = True
        for node, axis in zip(self._nodes, self.axes, strict=True):
            if c.state_of(bringup.wait_statusword(node, axis)) == "OPERATION ENABLED":
                node.controlword = c.CW_QUICK_STOP
                bringup.wait_statusword(node, axis)
            node.controlword = c.CW_DISABLE_VOLTAGE
        for node, axis in zip(self._nodes, self.axes, strict=True):
            bringup.wait_statusword(node, axis)

    def _estop_input(self) -> bool:
        link = self._link  # each drive's input rides in its TPDO1 statusword (bit 14)
        if link is None:
            return False
        with link.lock:
            return any(sw & c.SW_ESTOP_INPUT for sw in link.statusword)

    def _limit_input(self) -> str | None:
        """Statusword bit 11 (in every TPDO1) says a drive's limit switch is open; its 0x60FD
        then says which, read once by SDO."""
        return machine_io.limit_input(self._link, self._nodes, self.axes)

    def at_speed_input(self) -> bool:
        self._check_comm()  # an SDO a motion cycle while the machine waits at a spindle start
        return machine_io.at_speed_input(self._nodes, self.axes, self.o)

    @property
    def at_speed_input_name(self) -> str:  # type: ignore[override]
        return f"CANopen node {self.o.io_node}, 0x60FD bit 16"

    def _write_outputs(self, image: OutputImage) -> None:
        self._check_comm()
        last = self._io_written if self._io_written_link is self._link else None
        machine_io.write_outputs(self._nodes, self.axes, self.o, image, last)
        self._io_written, self._io_written_link = image, self._link  # this link's

    def _probe_input(self) -> bool | None:
        """Statusword bit 15 (the probe input's level, in every TPDO1); None unless the
        option touch_probe says a probe is wired."""
        link = self._link
        if not self.o.touch_probe or link is None:
            return None
        with link.lock:
            return any(sw & c.SW_PROBE_INPUT for sw in link.statusword)

    def arm_probe(self, toward: bool) -> None:
        self._check_comm()
        machine_io.arm_touch_probe(self._nodes, self.axes, toward)
        self._probe_toward = toward

    def probe_latch_pulses(self) -> np.ndarray | None:
        link = self._check_comm()
        counts = machine_io.touch_probe_latch(self._nodes, self.axes, self._probe_toward)
        if counts is None:
            return None
        with link.lock:
            return np.array([link.pulses(i, n) for i, n in enumerate(counts)], dtype=np.int64)

    # -- bench and probe ------------------------------------------------------------------
    def link_stats(self) -> dict[str, float | int]:
        """SYNC -> TPDO1 round trip (ms: p50, p99, max), late/missed TPDOs, late SYNCs; after
        close, those of the last session."""
        link = self._link
        stats = self._last_stats if link is None else link.stats()
        return stats | {"bringup_s": self.bringup_s}

    def rtt_samples_ms(self) -> np.ndarray:
        """Every SYNC -> TPDO1 round trip of the session (ms), for pooled percentiles."""
        link = self._link
        if link is None:
            return self._last_rtt_ms
        with link.lock:
            return np.array(link.rtt_s) * 1e3

    def drive_states(self) -> list[str]:
        """CiA 402 state of each drive from its last TPDO1."""
        link = self._require_link()
        with link.lock:
            return [c.state_of(sw) for sw in link.statusword]

    @property
    def discarded_counts(self) -> np.ndarray:
        link = self._require_link()
        with link.lock:
            return link.discarded.copy()

    def _probe(self) -> None:
        bringup.probe(self.o, self.axes)
