"""Homing mode (6) of a simulated CiA 402 drive: methods 1/2/17/18 on a simulated switch."""

from __future__ import annotations

from controller.config import AxisConfig
from drivers.canopen import cia402 as c
from drivers.homing import SEARCH_MARGIN, HomingPlan
from drivers.sim.homing import AxisHoming
from drivers.sim.switches import SimSwitches

METHODS = {method: key for key, method in c.HOMING_METHODS.items()}  # -> (direction, index)


class SimHoming402:
    """0x607C, 0x6098, 0x6099:1/2 and 0x609A as written by the master; a rising edge of
    controlword bit 4 in OPERATION ENABLED starts the method (drivers/sim/homing.py, CiA 402
    style: search, leave the switch at zero speed, the release edge or the next index pulse is
    the home point); halt (bit 8) interrupts it. Once the axis stands at the home point its
    position is set to the home offset, and statusword bits 10/12/13 say how it went."""

    def __init__(self, axis: AxisConfig, index: int, counts_per_mm: float, period_s: float,
                 switches: SimSwitches, search_limit_mm: float | None) -> None:
        self.axis, self.index, self.cpm, self.period_s = axis, index, counts_per_mm, period_s
        self.switches = switches
        lo, hi = axis.travel_mm
        self.search_limit_mm = search_limit_mm if search_limit_mm is not None \
            else (hi - lo) * (1.0 + SEARCH_MARGIN)
        self.method = 0
        self.search_counts_s = self.zero_counts_s = self.accel_counts_s2 = 0
        self.home_offset_counts = 0
        self.seq: AxisHoming | None = None
        self.result = "idle"  # idle, running, attained, error, interrupted
        self.error = ""

    def write(self, index: int, subindex: int, value: int) -> None:
        """The homing objects, as the SDO server receives them."""
        if index == c.HOMING_METHOD:
            self.method = value
        elif index == c.HOMING_SPEEDS and subindex == 1:
            self.search_counts_s = value
        elif index == c.HOMING_SPEEDS and subindex == 2:
            self.zero_counts_s = value
        elif index == c.HOMING_ACCEL:
            self.accel_counts_s2 = value
        elif index == c.HOME_OFFSET:
            self.home_offset_counts = value

    @property
    def running(self) -> bool:
        return self.seq is not None

    def start(self, ref_counts: int) -> None:
        """Rising edge of bit 4: start the configured method from where the axis stands."""
        direction, use_index = METHODS.get(self.method, (0, False))
        if not direction or not 0 < self.zero_counts_s <= self.search_counts_s \
                or self.accel_counts_s2 <= 0:
            self.seq, self.result = None, "error"
            self.error = f"method {self.method} or its speeds/acceleration are not supported"
            return
        plan = HomingPlan(axis=self.axis.name, direction=direction,
                          search_mm_s=self.search_counts_s / self.cpm,
                          latch_mm_s=self.zero_counts_s / self.cpm,
                          accel_mm_s2=self.accel_counts_s2 / self.cpm,
                          home_mm=self.home_offset_counts / self.cpm, final_mm=None,
                          use_index=use_index, search_limit_mm=self.search_limit_mm)
        self.seq = AxisHoming(plan, ref_counts / self.cpm, 1.0 / self.cpm, self.period_s,
                              self.switches.switch_for(self.index, plan),
                              self.switches.index_pitch_mm, release_latch=True)
        self.result, self.error = "running", ""

    def halt(self) -> None:
        if self.seq is not None:
            self.seq.halt("halted by the master")

    def interrupt(self) -> None:
        """Fault, disable or a mode change: the sequence is abandoned."""
        if self.seq is not None:
            self.seq, self.result = None, "interrupted"

    def command(self) -> int:
        """The new position demand (counts) for this SYNC."""
        assert self.seq is not None
        return int(round(self.seq.command() * self.cpm))

    def observe(self, actual_mm: float) -> int:
        """After the SYNC's servo step: counts to add to the drive's position (at attained)."""
        seq = self.seq
        assert seq is not None
        offset_mm = self.switches.offset_mm
        shift = seq.observe(actual_mm + offset_mm[self.index], actual_mm)
        if shift:
            offset_mm[self.index] -= shift / self.cpm
        if seq.finished:
            self.seq = None
            halted = seq.error == "halted by the master"
            self.result = "attained" if not seq.error else "interrupted" if halted else "error"
            self.error = seq.error
        return shift

    def status_bits(self) -> int:
        """Statusword bits 10 (target reached), 12 (attained) and 13 (error) in mode 6."""
        if self.seq is not None:
            return c.SW_HOMING_ERROR if self.seq.error else 0
        return {"attained": c.SW_HOMING_ATTAINED | c.SW_TARGET_REACHED,
                "error": c.SW_HOMING_ERROR | c.SW_TARGET_REACHED}.get(self.result,
                                                                     c.SW_TARGET_REACHED)
