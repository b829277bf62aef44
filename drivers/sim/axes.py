"""The simulated card's axes: Table II servo model per axis plus fault injections."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from controller.config import MachineConfig
from controller.servo.model import discretise
from controller.servo.plant_option import PlantOptionError, plant_config
from controller.servo.stacked import StackedFilter
from drivers.errors import DriveUnavailableError


def plant_of(config: MachineConfig, options: Mapping[str, Any], prefix: str) -> MachineConfig:
    """The machine a simulated drive runs, from its plant options (servo/plant_option.py); a
    bad one is refused before anything opens, the message prefix + the option's own."""
    try:
        return plant_config(config, options)
    except PlantOptionError as exc:
        raise DriveUnavailableError(f"{prefix}{exc}") from None


class SimAxes:
    """Commanded step counters, servo lag, encoders; stall/lag/freeze injections per axis.

    Convention of controller.servo.model: r[k] = accumulated pulses * pulse_mm,
    v[k] = (r[k] - r[k-1]) / T drives the E/V filter, actual = r - e.
    """

    def __init__(self, config: MachineConfig, start_counts: np.ndarray) -> None:
        self.period_s = config.sample_period_s
        self.pulse_mm = np.array([a.pulse_mm for a in config.axes])
        # All axes' plants in one filter: a period's frame costs one call, not one per axis.
        self.servo = StackedFilter([discretise(a.servo, self.period_s) for a in config.axes])
        self.commanded = start_counts.astype(np.int64).copy()
        self.actual_mm = self.commanded * self.pulse_mm
        n = len(config.axes)
        self.frozen = np.zeros(n, dtype=bool)  # stalled or coasting after a drive fault
        self.frozen_mm = np.zeros(n)
        self.extra_lag_mm = np.zeros(n)
        self.lag_target_mm = np.zeros(n)
        self.lag_step_mm = np.zeros(n)
        self._injected = False

    def step(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clock frames (n, n_axes) through the axes: (commanded counts, encoder counts) rows."""
        cmd = self.commanded + frames.cumsum(axis=0)
        r_mm = cmd * self.pulse_mm
        v_mm_s = frames * self.pulse_mm / self.period_s
        err = self.servo.step(v_mm_s)
        actual = r_mm - err
        # Nothing injected (every streamed block): no lag rows to subtract (x - 0.0 is x) and
        # no axis to hold, three numpy calls fewer a block.
        if self.injected:
            actual -= self._lag_rows(frames.shape[0])
            actual[:, self.frozen] = self.frozen_mm[self.frozen]
        if frames.shape[0]:
            self.commanded = cmd[-1].copy()
            self.actual_mm = actual[-1].copy()
        return cmd, self.encoder(actual)

    @property
    def injected(self) -> bool:
        """A lag or a frozen axis injected (since the axes were made: never cleared)."""
        return self._injected

    def snapshot(self) -> tuple[np.ndarray, ...]:
        """What stepping changes: a block clocked ahead can be taken back (block_clock.py)."""
        return (self.commanded.copy(), self.actual_mm.copy(), self.servo.state.copy(),
                self.extra_lag_mm.copy())

    def restore(self, snap: tuple[np.ndarray, ...]) -> None:
        self.commanded, self.actual_mm, self.servo.state, self.extra_lag_mm = (
            a.copy() for a in snap)

    def encoder(self, actual_mm: np.ndarray) -> np.ndarray:
        return np.rint(actual_mm / self.pulse_mm).astype(np.int64)

    def _lag_rows(self, n: int) -> np.ndarray:
        # Injected lag ramps towards its target so the encoder does not jump.
        k = np.arange(1, n + 1)[:, None]
        lag = self.extra_lag_mm + self.lag_step_mm * k
        lag = np.minimum(lag, np.maximum(self.lag_target_mm, self.extra_lag_mm))
        if n:
            self.extra_lag_mm = lag[-1].copy()
        return lag

    def freeze(self, axis: int) -> None:
        self.frozen[axis] = True
        self._injected = True
        self.frozen_mm[axis] = self.actual_mm[axis]

    def add_lag(self, axis: int, lag_mm: float, ramp_frames: int) -> None:
        self._injected = True
        self.lag_target_mm[axis] = self.extra_lag_mm[axis] + lag_mm
        self.lag_step_mm[axis] = lag_mm / max(1, ramp_frames)

    def rebase(self, axis: int, shift_counts: int) -> None:
        """Homing: the counters of one axis jump by shift_counts (the table does not move)."""
        shift_mm = shift_counts * self.pulse_mm[axis]
        self.commanded[axis] += shift_counts
        self.actual_mm[axis] += shift_mm
        self.frozen_mm[axis] += shift_mm
