"""A drive whose hardware latches its position at the probe's edge (CANopen's touch probe):
armed at the start of a G38 move, read once the machine is at rest, exact to the drive's
counts instead of the cycle the host saw the contact in."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class ProbeLatch(ABC):
    """Mixed into a Drive beside its probe_input() (which still says when the probe trips)."""

    @abstractmethod
    def arm_probe(self, toward: bool) -> None:
        """Latch at the next edge: contact made (toward: G38.2/G38.3) or lost (G38.4/G38.5)."""

    @abstractmethod
    def probe_latch_pulses(self) -> np.ndarray | None:
        """Every axis's position at the armed edge (pulses), or None if a drive latched none;
        the probe is switched off again."""
