"""A drive that sets outputs as it clocks a given frame (M62/M63/M67 travel with the frames):
the sim card. Other drives have them set by the motion loop once that frame is fed back."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

from controller.blocks import OutputChange


class FrameOutputs(ABC):
    """Mixed into a Drive whose frame clock can set outputs."""

    @abstractmethod
    def schedule_outputs(self, changes: Sequence[OutputChange], frames_back: int) -> None:
        """Set these outputs (as set_outputs does) when the frame `frames_back` before the
        last one queued is clocked (0: the last one queued)."""
