"""Shared helpers for the runtime tests: config, virtual sim card, recorder, smoothness check."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig, load_config
from drivers.base import Feedback
from drivers.sim.card import SimCard


def xy_config() -> MachineConfig:
    return load_config("xy_table_paper")


def virtual_card(config: MachineConfig, **options: object) -> SimCard:
    card = SimCard(config, realtime=False, **options)
    card.open()
    return card


class Recorder:
    """Wraps a drive's feedback() to keep every executed frame (like LinuxCNC halsampler)."""

    def __init__(self, drive: SimCard) -> None:
        self.parts: list[Feedback] = []
        self._inner = drive.feedback
        drive.feedback = self._feedback  # type: ignore[method-assign]

    def _feedback(self) -> Feedback:
        fb = self._inner()
        self.parts.append(fb)
        return fb

    def commanded(self) -> np.ndarray:
        """Commanded counts of every executed frame; none when the run stopped before moving
        (a fault can be seen before the first frame when the machine is loaded)."""
        parts = [p.commanded_counts for p in self.parts if len(p)]
        return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)


def assert_smooth(cmd_counts: np.ndarray, start_counts: np.ndarray, config: MachineConfig) -> None:
    """No commanded position jump: |dp| <= Vmax T and |d2p| <= Amax T^2, plus pulse rounding."""
    t = config.sample_period_s
    pulse = config.axes[0].pulse_mm
    if len(cmd_counts) == 0:
        return  # stopped before the first frame: nothing moved, so nothing jumped
    p = np.vstack([start_counts, start_counts, cmd_counts])
    d1 = np.abs(np.diff(p, axis=0)).max()
    d2 = np.abs(np.diff(p, n=2, axis=0)).max()
    vmax = max(config.interpolator.max_feed_mm_s, config.interpolator.rapid_feed_mm_s)
    assert d1 <= vmax * t / pulse + 1, f"step of {d1} pulses in one sample"
    assert d2 <= config.interpolator.max_accel_mm_s2 * t * t / pulse * 1.5 + 2, \
        f"acceleration jump of {d2} pulses/sample^2"
