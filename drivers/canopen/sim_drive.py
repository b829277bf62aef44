"""Simulated CiA 402 drives: a canopen LocalNode per axis, CSP through the Table II servo model."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from typing import Any

import canopen
import numpy as np
from canopen.sdo import SdoAbortedError

from controller.config import AxisConfig, MachineConfig
from controller.errors import DriveError
from controller.servo.model import AxisServoStepper, discretise
from controller.servo.plant_option import PLANT_OPTIONS
from drivers.canopen import cia402 as c
from drivers.canopen.options import drive_layout
from drivers.canopen.sim_homing import SimHoming402
from drivers.canopen.sim_inject import (
    SDO_ABORT_VALUE_RANGE,
    Injections,
    injections,
    opt_float,
    opt_int,
)
from drivers.canopen.sim_io import SimIo402
from drivers.canopen.sim_probe import PROBE_OPTIONS
from drivers.io_peer import IO_OPTIONS
from drivers.sim.axes import plant_of
from drivers.sim.switches import SWITCH_OPTIONS, SimSwitches

LAG_RAMP_SYNCS = 20  # injected lag ramps in over this many cycles (as drivers/sim/axes.py)
WATCHDOG_PERIOD_S = 0.01


class SimAxis402:
    """One drive: SDO server, NMT slave and EMCY producer (LocalNode) plus what LocalNode lacks:
    the CiA 402 state machine, synchronous RPDO latching, TPDO1 on SYNC, CSP on the servo model,
    following-error supervision (0x6065/0x6066) and the master-heartbeat consumer (0x1016)."""

    def __init__(self, network: canopen.Network, node_id: int, axis: AxisConfig,
                 counts_per_mm: float, period_s: float, inject: Injections,
                 homing: SimHoming402, io: SimIo402, index: int) -> None:
        self.node = canopen.LocalNode(node_id, canopen.import_od(str(c.EDS_PATH), node_id))
        network.add_node(self.node)
        self.network, self.id, self.name = network, node_id, axis.name
        self.counts_per_mm, self.period_s, self.inject = counts_per_mm, period_s, inject
        self.homing, self.io, self.index = homing, io, index  # index: the axis's, for its I/O
        self.stepper = AxisServoStepper(discretise(axis.servo, period_s))
        self.lock = threading.RLock()
        od = self.node.object_dictionary
        self.rpdo_cob = od[c.RPDO1_COMM][1].default
        self.tpdo_cob = od[c.TPDO1_COMM][1].default
        network.subscribe(self.rpdo_cob, self._on_rpdo)
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.state = "SWITCH ON DISABLED"
        self.mode = 0
        self.controlword = 0
        self.latched: tuple[int, int] | None = None  # RPDO1 (controlword, target), next SYNC
        self.target = self.ref = self.position = 0  # counts
        self.actual_mm = 0.0
        self.error_code = 0
        self.window, self.timeout_ms, self.abort_option = 2000, 10, 1
        self.consumer_id, self.consumer_ms = 0, 0
        self.ferror_syncs = 0
        self.lag_mm = self.lag_target_mm = 0.0
        self.silent = False
        self.syncs_enabled = 0  # SYNC cycles since the first enable: the injection clock
        self.tpdos_sent = 0
        self.emcy_sent: list[int] = []
        self.node.nmt.send_command(0x80)  # boot into PRE-OPERATIONAL

    # -- SDO and RPDO ---------------------------------------------------------------------
    def _on_read(self, index: int, subindex: int, od: Any) -> int | None:
        live = {c.STATUSWORD: self.statusword, c.POSITION_ACTUAL: self.position,
                c.MODE_DISPLAY: self.mode, c.ERROR_CODE: self.error_code,
                c.ERROR_REGISTER: 0x01 if self.state == "FAULT" else 0,
                0x6062: self.ref, 0x60F4: self.ref - self.position,
                c.DIGITAL_INPUTS: self.io.digital_inputs(self.index)}
        with self.lock:
            value = live.get(index)
            return value if value is not None else self.io.probe.read(self.index, index)

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        if self.silent:
            raise SdoAbortedError(0x08000000)
        if index == self.inject.sdo_abort_index:
            raise SdoAbortedError(SDO_ABORT_VALUE_RANGE)
        value = od.decode_raw(data)
        with self.lock:
            if index == c.CONTROLWORD:
                self.command(int(value))
            elif index == c.MODE:
                if int(value) in (c.MODE_CSP, c.MODE_HOMING) and int(value) != self.mode:
                    self.homing.interrupt()
                    self.mode = int(value)
            elif index == c.TARGET_POSITION:
                self.target = int(value)
            elif index == c.FERROR_WINDOW:
                self.window = int(value)
            elif index == c.FERROR_TIMEOUT:
                self.timeout_ms = int(value)
            elif index == c.ABORT_CONNECTION:
                self.abort_option = int(value)
            elif self.io.write(index, subindex, value):
                pass  # an output: recorded by SimIo402
            elif self.io.probe.write(self.index, index, int(value)):
                pass  # the touch probe armed (or switched off)
            elif index == c.CONSUMER_HEARTBEAT and subindex == 1:
                self.consumer_id, self.consumer_ms = (int(value) >> 16) & 0x7F, int(value) & 0xFFFF
            else:
                self.homing.write(index, subindex, int(value))

    def _on_rpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) != c.PDO1.size or self.node.nmt.state != "OPERATIONAL":
            return
        with self.lock:
            self.latched = c.PDO1.unpack_from(data)

    # -- CiA 402 state machine ------------------------------------------------------------
    def command(self, cw: int) -> None:
        """Apply a controlword (an SDO write does it at once, RPDO1 at the next SYNC)."""
        rising_reset = cw & c.CW_FAULT_RESET and not self.controlword & c.CW_FAULT_RESET
        rising_start = cw & c.CW_HOMING_START and not self.controlword & c.CW_HOMING_START
        self.controlword = cw
        self._command_state(cw, rising_reset)
        if self.state != "OPERATION ENABLED" or self.mode != c.MODE_HOMING:
            self.homing.interrupt()
        elif cw & c.CW_HALT:
            self.homing.halt()
        elif rising_start:
            self.homing.start(self.ref)

    def _command_state(self, cw: int, rising_reset: int) -> None:
        s = self.state
        if s == "FAULT":
            if rising_reset:
                self.state, self.error_code = "SWITCH ON DISABLED", 0
                self.node.emcy.reset()
            return
        if not cw & 0x02:  # disable voltage (7, 9, 10, 12)
            self.state = "SWITCH ON DISABLED"
        elif not cw & 0x04:  # quick stop
            self.state = "QUICK STOP ACTIVE" if s in ("OPERATION ENABLED", "QUICK STOP ACTIVE") \
                else "SWITCH ON DISABLED"
        elif cw & 0x0F == c.CW_SHUTDOWN:  # 2, 6, 8
            if s in ("SWITCH ON DISABLED", "SWITCHED ON", "OPERATION ENABLED"):
                self.state = "READY TO SWITCH ON"
        elif cw & 0x0F == c.CW_SWITCH_ON:  # 3, 5
            if s in ("READY TO SWITCH ON", "OPERATION ENABLED"):
                self.state = "SWITCHED ON"
        elif cw & 0x0F == c.CW_ENABLE_OPERATION:  # 3 + 4, 4, 16
            if s in ("READY TO SWITCH ON", "SWITCHED ON", "QUICK STOP ACTIVE"):
                self.state = "OPERATION ENABLED"

    @property
    def statusword(self) -> int:
        sw = c.STATE_BITS[self.state] | c.SW_REMOTE
        if self.state in ("READY TO SWITCH ON", "SWITCHED ON", "OPERATION ENABLED",
                          "QUICK STOP ACTIVE"):
            sw |= c.SW_VOLTAGE_ENABLED
        if self.mode == c.MODE_HOMING:
            return sw | self.homing.status_bits()
        if self.state == "OPERATION ENABLED" and self.mode == c.MODE_CSP:
            sw |= c.SW_FOLLOWS_COMMAND
        if abs(self.ref - self.position) > self.window:
            sw |= c.SW_FOLLOWING_ERROR
        if self.inject.estop_input_file and os.path.exists(self.inject.estop_input_file):
            sw |= c.SW_ESTOP_INPUT
        return sw | self.io.statusword_bits(self.index)

    def fault(self, code: int) -> None:
        """Fault reaction: power off (the axis holds where it is in the model), EMCY."""
        with self.lock:
            if self.state == "FAULT" or self.silent:
                return
            self.state, self.error_code = "FAULT", code
            self.homing.interrupt()
        self.emcy_sent.append(code)
        self.node.emcy.send(code, 0x01 if code != c.EMCY_HEARTBEAT else 0x11)

    def mute(self) -> None:
        """Power loss / pulled cable: no heartbeat, no PDO, no EMCY, no SDO answer."""
        with self.lock:
            self.silent = True
        self.node.nmt.stop_heartbeat()
        self.network.unsubscribe(self.node.sdo.rx_cobid)

    # -- one SYNC -------------------------------------------------------------------------
    def step(self) -> bool:
        """The SYNC's step (latched RPDO1, state, servo model, following error); False: this
        drive answers no TPDO1 (silent, or not OPERATIONAL)."""
        with self.lock:
            if self.silent or self.node.nmt.state != "OPERATIONAL":
                return False
            if self.latched is not None:
                cw, self.target = self.latched
                self.latched = None
                self.command(cw)
            enabled = self.state == "OPERATION ENABLED"
            if enabled or self.syncs_enabled:
                self.syncs_enabled += 1
            self._injections()
            if self.silent:
                return False
            homing = enabled and self.mode == c.MODE_HOMING and self.homing.running
            if enabled and self.mode == c.MODE_CSP:
                new_ref = self.target
            elif homing:
                new_ref = self.homing.command()
            else:  # disabled, quick stop, fault: the reference stays (the motor holds)
                new_ref = self.ref
            v_mm_s = (new_ref - self.ref) / self.counts_per_mm / self.period_s
            self.ref = new_ref
            err_mm = float(self.stepper.step(np.array([v_mm_s]))[0])
            self.lag_mm = min(self.lag_target_mm,
                              self.lag_mm + self.inject.lag_mm / LAG_RAMP_SYNCS)
            self.actual_mm = self.ref / self.counts_per_mm - err_mm - self.lag_mm
            self.position = int(round(self.actual_mm * self.counts_per_mm))
            if homing and (shift := self.homing.observe(self.actual_mm)):
                self._rebase(shift)
            over = abs(self.ref - self.position) > self.window and enabled
            self.ferror_syncs = self.ferror_syncs + 1 if over else 0
            trip = self.ferror_syncs * self.period_s * 1e3 > self.timeout_ms
        if trip:
            self.fault(c.EMCY_FOLLOWING_ERROR)
        return True

    def send_tpdo(self) -> None:
        """TPDO1 (statusword, position actual) as they stand after the SYNC's step."""
        with self.lock:
            data = c.PDO1.pack(self.statusword, self.position)
        self.network.send_message(self.tpdo_cob, data)
        self.tpdos_sent += 1

    def _rebase(self, shift: int) -> None:
        """Homing attained: the position reads the home offset (the table does not move)."""
        self.ref += shift
        self.target = self.ref
        self.position += shift
        self.actual_mm += shift / self.counts_per_mm

    def _injections(self) -> None:
        t_s = self.syncs_enabled * self.period_s
        inj = self.inject
        if inj.fault_after_s is not None and t_s >= inj.fault_after_s:
            inj.fault_after_s = None  # once: a fault reset then clears it
            self.fault(inj.fault_code)
        if inj.lag_mm and t_s >= inj.lag_after_s and self.lag_target_mm == 0.0:
            self.lag_target_mm = abs(inj.lag_mm)
        if inj.silent_after_s is not None and t_s >= inj.silent_after_s:
            self.mute()

    def master_heartbeat_lost(self, age_s: float) -> None:
        """0x1016 consumer time elapsed: 0x6007 says what to do (1 fault, 2 disable, 3 qs)."""
        with self.lock:
            if self.state not in ("OPERATION ENABLED", "QUICK STOP ACTIVE", "SWITCHED ON"):
                return
            option = self.abort_option
            if option == 2:
                self.state = "SWITCH ON DISABLED"
            elif option == 3:
                self.state = "QUICK STOP ACTIVE"
        if option == 1:
            self.fault(c.EMCY_HEARTBEAT)


class SimDriveSet:
    """The simulated drives of a machine on one CAN bus (in-process python-can `virtual` by
    default). Options (strict): drive_fault_after_s, drive_fault_code, lag_mm, lag_after_s,
    silent_after_s, sdo_abort_index, fault_axis (x); times count from the first enable;
    estop_input_file (every drive's e-stop input is open while that file exists);
    limit_input_file, outputs_file (machine I/O: drivers/canopen/sim_io.py), probe_workpiece_mm
    (the touch probe's work: drivers/canopen/sim_probe.py).
    Homing (mode 6): true_start_mm, home_switch_mm (default: at the home offset the master
    writes; null: no switch), index_pitch_mm (drivers/sim/switches.py) and search_limit_mm
    (default: the travel + 10 %: then statusword bit 13). Each axis's loop: plant_x, plant_y,
    plant_z, plant_pole_pct, plant_gain_pct (controller/servo/plant_option.py)."""

    OPTIONS = frozenset({"drive_fault_after_s", "drive_fault_code", "lag_mm", "lag_after_s",
                         "silent_after_s", "sdo_abort_index", "fault_axis", "true_start_mm",
                         "home_switch_mm", "index_pitch_mm", "search_limit_mm",
                         "estop_input_file"}) | PLANT_OPTIONS | IO_OPTIONS | PROBE_OPTIONS

    def __init__(self, config: MachineConfig, options: dict[str, Any] | None = None,
                 channel: str = "cncsim", interface: str = "virtual",
                 watchdog: bool = True) -> None:
        options = dict(options or {})
        unknown = sorted(set(options) - self.OPTIONS)
        if unknown:
            raise DriveError(f"unknown simulated drive option(s): {', '.join(unknown)} "
                             f"(have: {', '.join(sorted(self.OPTIONS))})")
        plant = plant_of(config, {k: v for k, v in options.items() if k in PLANT_OPTIONS},
                         "simulated drive option ")
        layout = drive_layout(config)
        names = config.axis_names
        fault_axis = str(options.get("fault_axis", names[0]))
        if fault_axis not in names:
            raise DriveError(f"fault_axis {fault_axis!r} is not an axis ({', '.join(names)})")
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = 0.05  # a quick close
        self.network.connect(interface=interface, channel=channel, receive_own_messages=False)
        self.master_id = layout.master_node_id
        self.axes: list[SimAxis402] = []
        self.switches = SimSwitches(len(names), {k: v for k, v in options.items()
                                                 if k in SWITCH_OPTIONS}, np.zeros(len(names)),
                                    "simulated drive")
        search_limit_mm = opt_float(options, "search_limit_mm")
        self.io = SimIo402(options, names, config.io.spindle)
        for i, (axis, node_id, cpm) in enumerate(zip(plant.axes, layout.node_ids,
                                                     layout.counts_per_mm, strict=True)):
            inject = injections(options) if axis.name == fault_axis else Injections(
                sdo_abort_index=opt_int(options, "sdo_abort_index"))
            inject.estop_input_file = options.get("estop_input_file")
            homing = SimHoming402(axis, i, cpm, config.sample_period_s, self.switches,
                                  search_limit_mm)
            self.axes.append(SimAxis402(self.network, node_id, axis, cpm,
                                        config.sample_period_s, inject, homing, self.io, i))
        self.master_seen_s: float | None = None
        self.host_pending: Callable[[], bool] = lambda: False  # frames from the master unread
        self._last_watch_s = time.monotonic()
        self.syncs = 0
        self.network.subscribe(0x80, self._on_sync)
        self.network.subscribe(0x700 + self.master_id, self._on_master_heartbeat)
        self._stop = threading.Event()
        self._thread = None
        if watchdog:
            self._thread = threading.Thread(target=self._watchdog, name="sim402-hb", daemon=True)
            self._thread.start()

    def axis(self, name: str) -> SimAxis402:
        return next(a for a in self.axes if a.name == name)

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.on_sync()

    def on_sync(self) -> None:
        """One SYNC: every drive applies its latched RPDO and steps, the probe input (wired to
        every drive) is looked at where the table now is, then each answers its TPDO1."""
        self.syncs += 1
        stepped = [axis.step() for axis in self.axes]
        self.io.probe.observe([a.actual_mm for a in self.axes], [a.counts_per_mm for a in
                                                                  self.axes])
        for axis, answers in zip(self.axes, stepped, strict=True):
            if answers:
                axis.send_tpdo()

    def _on_master_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.master_seen_s = time.monotonic()

    def check_master(self, now_s: float | None = None) -> None:
        """Heartbeat consumer (CiA 301: armed by the first heartbeat received)."""
        if self.master_seen_s is None:
            return
        age_s = (now_s if now_s is not None else time.monotonic()) - self.master_seen_s
        for axis in self.axes:
            if axis.consumer_ms and axis.consumer_id == self.master_id \
                    and age_s * 1e3 > axis.consumer_ms:
                axis.master_heartbeat_lost(age_s)

    def _watchdog(self) -> None:
        while not self._stop.wait(WATCHDOG_PERIOD_S):
            self.watch(time.monotonic())

    def watch(self, now_s: float) -> None:
        """One look of the heartbeat consumer, with two allowances a real drive does not
        need: a look that itself came late (this process starved of CPU) does not count the
        time it slept, and none is made while frames from the master wait unread (they hold
        its heartbeats: the master is not silent, this simulator is behind)."""
        overslept_s = now_s - self._last_watch_s - 2 * WATCHDOG_PERIOD_S
        self._last_watch_s = now_s
        if overslept_s > 0 and self.master_seen_s is not None:
            self.master_seen_s += overslept_s
        if not self.host_pending() and not self._frames_queued():
            self.check_master(now_s)

    def _frames_queued(self) -> bool:
        """Frames on the bus not yet handed to our receivers (python-can's virtual bus)."""
        queue = getattr(self.network.bus, "queue", None)
        return queue is not None and queue.qsize() > 0

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        for axis in self.axes:
            axis.node.nmt.stop_heartbeat()
        self.network.disconnect()
