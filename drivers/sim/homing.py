"""Simulated homing, drive side: one axis's sequence sample by sample (switch, index, counters).

What a drive or a card runs on its own servo plant; the three simulators share it (the sim card,
the serial card's peer, the simulated CiA 402 drive). Two frames: the counter frame (what the
step counter and encoder read) and the true frame (where the table really is: the home switch
and the encoder's index marks are there). The switch is active on the search side of its edge:
direction * (true - switch_mm) >= 0.

Sequences (both stop with the planned acceleration between moves):
- card (LinuxCNC style): search at search speed toward `direction` until the switch trips,
  back off at search speed until it releases, approach again at latch speed: the point found
  is where it trips (with use_index: the next index mark on, in the same direction).
- CiA 402 methods 17/18 (1/2 with the index): search until the switch trips, then leave it at
  latch speed: the point found is where it releases (with use_index: the next index mark on,
  away from the switch).
The counters are then shifted so the point found reads home_mm, and the axis moves to final_mm
(or, final_mm None, back to the point found, the shift applied once it stands there: a drive
sets its position to the home offset when homing is attained).
"""

from __future__ import annotations

import math

import numpy as np

from drivers.homing import HomingPlan
from drivers.sim.axes import SimAxes

SEARCH, STOP, BACKOFF, LATCH, RELEASE, INDEX, FINAL, SETTLE, DONE, FAILED = range(10)
# Done once in position (within half a count) for SETTLE_HOLD_S in a row, as a drive's position
# window has a time (CiA 402's 0x6068): the servo rings after the final move, and an axis that
# passed through the half count in a swing read a count off 10-25 ms later. At the latest
# SETTLE_MAX_S after the final move.
SETTLE_HOLD_S = 0.03
SETTLE_MAX_S = 0.5


class AxisHoming:
    """One axis: command() before each sample (the new reference), observe() after it."""

    def __init__(self, plan: HomingPlan, ref_mm: float, unit_mm: float, period_s: float,
                 switch_mm: float | None, index_pitch_mm: float,
                 release_latch: bool = False) -> None:
        self.plan, self.unit_mm, self.period_s = plan, unit_mm, period_s
        self.switch_mm, self.pitch_mm, self.release_latch = switch_mm, index_pitch_mm, release_latch
        self.ref_mm = self.start_mm = ref_mm  # commanded position, counter frame
        self.v_mm_s = 0.0
        self.dv_mm_s = plan.accel_mm_s2 * period_s
        self.stage, self.after_stop = SEARCH, SEARCH
        self.move_dir = plan.direction
        self.mark_mm = self.target_mm = 0.0
        self.pending_shift = 0  # counts, applied once the axis stands at the point found
        self.settle_samples = 0
        self.in_position_samples = 0  # in a row, while settling
        self.error = ""
        self.found_true_mm: float | None = None  # the point found, true frame

    @property
    def finished(self) -> bool:
        return self.stage in (DONE, FAILED)

    def active(self, true_mm: float) -> bool:
        return self.switch_mm is not None and self.plan.direction * (true_mm - self.switch_mm) >= 0

    def halt(self, reason: str, at_once: bool = False) -> None:
        """Stop the sequence as failed: decelerate first (or stop dead: the drive is off)."""
        if self.finished:
            return
        self.error = self.error or reason
        if at_once:
            self.stage, self.v_mm_s = FAILED, 0.0
        else:
            self._stop_then(FAILED)

    def _stop_then(self, stage: int) -> None:
        self.stage, self.after_stop = STOP, stage

    # -- one sample -----------------------------------------------------------------------
    def command(self) -> float:
        """Advance the reference by one sample; the new commanded position (counter frame)."""
        p, st = self.plan, self.stage
        if st == SEARCH:
            vt = p.direction * p.search_mm_s
        elif st == BACKOFF:
            vt = -p.direction * p.search_mm_s
        elif st in (LATCH, RELEASE, INDEX):
            vt = self.move_dir * p.latch_mm_s
        elif st == FINAL:
            d = self.target_mm - self.ref_mm
            vt = math.copysign(min(p.search_mm_s, math.sqrt(2.0 * p.accel_mm_s2 * abs(d))), d)
        else:
            vt = 0.0
        self.v_mm_s += min(max(vt - self.v_mm_s, -self.dv_mm_s), self.dv_mm_s)
        if st == STOP and self.v_mm_s == 0.0:
            self.stage = self.after_stop
        if st == FINAL and abs(self.target_mm - self.ref_mm) <= abs(self.v_mm_s) * self.period_s:
            self.ref_mm, self.v_mm_s, self.stage = self.target_mm, 0.0, SETTLE
            return self.ref_mm
        self.ref_mm += self.v_mm_s * self.period_s
        return self.ref_mm

    def observe(self, true_mm: float, actual_mm: float) -> int:
        """The table's true and counter-frame positions after the sample; returns the counts
        to add to the axis's counters now (nonzero once, when the point found is set)."""
        p, st = self.plan, self.stage
        travelled_mm = abs(self.ref_mm - self.start_mm)
        if st == SEARCH:
            if self.active(true_mm):
                self.move_dir = -p.direction if self.release_latch else p.direction
                self._stop_then(RELEASE if self.release_latch else BACKOFF)
            elif travelled_mm > p.search_limit_mm:
                self.halt(f"home switch not found within {p.search_limit_mm:.1f} mm "
                          "(the travel + 10 %)")
        elif st in (BACKOFF, RELEASE) and travelled_mm > 2.0 * p.search_limit_mm:
            self.halt("the home switch does not release")
        elif st == BACKOFF and not self.active(true_mm):
            self._stop_then(LATCH)
        elif st == LATCH and self.active(true_mm) or st == RELEASE and not self.active(true_mm):
            return self._edge(true_mm, actual_mm)
        elif st == INDEX and self.move_dir * (true_mm - self.mark_mm) >= 0:
            return self._found(self.mark_mm, true_mm, actual_mm)
        elif st == SETTLE:
            self.settle_samples += 1
            inside = abs(actual_mm - self.ref_mm) < 0.5 * self.unit_mm
            self.in_position_samples = self.in_position_samples + 1 if inside else 0
            if self.in_position_samples * self.period_s >= SETTLE_HOLD_S - 1e-12 \
                    or self.settle_samples * self.period_s >= SETTLE_MAX_S:
                self.stage = DONE
                shift, self.pending_shift = self.pending_shift, 0
                self.ref_mm += shift * self.unit_mm
                return shift
        return 0

    def _edge(self, true_mm: float, actual_mm: float) -> int:
        assert self.switch_mm is not None
        edge = self.switch_mm
        if not self.plan.use_index:
            return self._found(edge, true_mm, actual_mm)
        k = edge / self.pitch_mm  # the next mark strictly beyond the edge, moving on
        self.mark_mm = self.pitch_mm * (math.floor(k) + 1 if self.move_dir > 0
                                        else math.ceil(k) - 1)
        self.stage = INDEX
        return 0

    def _found(self, point_mm: float, true_mm: float, actual_mm: float) -> int:
        """The point found (true frame) is to read home_mm."""
        self.found_true_mm = point_mm
        at_mm = point_mm - (true_mm - actual_mm)  # what the counters read there now
        shift = round((self.plan.home_mm - at_mm) / self.unit_mm)
        self._stop_then(FINAL)
        if self.plan.final_mm is None:  # back to the point found, then the counters jump
            self.target_mm, self.pending_shift = at_mm, shift
            return 0
        self.ref_mm += shift * self.unit_mm
        self.target_mm = self.plan.final_mm
        return shift


class SimAxesHoming:
    """Some axes of a SimAxes homing together, sample by sample (the sim card, the serial
    card); the other axes hold. offset_mm (true - counter frame, per axis) is updated in place."""

    def __init__(self, axes: SimAxes, offset_mm: np.ndarray, seqs: dict[int, AxisHoming],
                 names: tuple[str, ...]) -> None:
        self.axes, self.offset_mm, self.seqs, self.names = axes, offset_mm, seqs, names
        self.samples = 0
        self.failed_axis: int | None = None

    @property
    def finished(self) -> bool:
        return all(s.finished for s in self.seqs.values())

    @property
    def error(self) -> str:
        """'' on success, else the first failed axis's reason."""
        return "" if self.failed_axis is None else self.seqs[self.failed_axis].error

    @property
    def failed_name(self) -> str | None:
        return None if self.failed_axis is None else self.names[self.failed_axis]

    def halt(self, reason: str, at_once: bool = False, axis: int | None = None) -> None:
        """Stop every axis as failed; `axis` (when homing) is the one named."""
        if axis in self.seqs:
            self.seqs[axis].halt(reason, at_once)
            self._note_failure()
        for s in self.seqs.values():
            s.halt(reason, at_once)
        self._note_failure()

    def step(self, n: int) -> int:
        """Clock up to n samples; returns how many were used (fewer once all have finished)."""
        axes, pulse = self.axes, self.axes.pulse_mm
        frame = np.zeros((1, len(pulse)), dtype=np.int64)
        for k in range(n):
            if self.finished:
                return k
            frame[:] = 0
            for i, s in self.seqs.items():
                if not s.finished:
                    frame[0, i] = round(s.command() / pulse[i]) - axes.commanded[i]
            axes.step(frame)
            for i, s in self.seqs.items():
                if not s.finished:
                    shift = s.observe(axes.actual_mm[i] + self.offset_mm[i], axes.actual_mm[i])
                    if shift:
                        axes.rebase(i, shift)
                        self.offset_mm[i] -= shift * pulse[i]
            self.samples += 1
            self._note_failure()
        return n

    def _note_failure(self) -> None:
        if self.failed_axis is not None:
            return
        failed = [i for i, s in self.seqs.items() if s.error]
        if failed:
            self.failed_axis = failed[0]
            name = self.names[failed[0]].upper()
            for i, s in self.seqs.items():
                if i != failed[0]:
                    s.halt(f"stopped: the {name} axis's homing failed")
