"""A drive that sets outputs as it clocks a given frame (M62/M63/M67 travel with the frames):
the sim card. Other drives have them set by the motion loop once that frame is fed back."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any

from controller.blocks import OutputChange


class FrameOutputs(ABC):
    """Mixed into a Drive whose frame clock can set outputs."""

    @abstractmethod
    def schedule_outputs(self, changes: Sequence[OutputChange], frames_back: int) -> None:
        """Set these outputs (as set_outputs does) when the frame `frames_back` before the
        last one queued is clocked (0: the last one queued)."""


class FrameOutputQueue:
    """A frame clock's scheduled outputs: (frame sequence number, changes), in order."""

    def __init__(self) -> None:
        self.waiting: list[tuple[int, Sequence[OutputChange]]] = []
        self.clocked: list[tuple[int, tuple]] = []  # (seq, changes) as set (tests read it)

    def due(self, clocked_seq: int, set_outputs: Callable[[Sequence[OutputChange]], Any]) -> None:
        """The frames up to clocked_seq are clocked: set what was scheduled on them."""
        while self.waiting and self.waiting[0][0] <= clocked_seq:
            seq, changes = self.waiting.pop(0)
            set_outputs(changes)
            self.clocked.append((seq, tuple(changes)))

    def taken_back(self, written: int) -> None:
        """Frames from `written` on were taken back: the motion loop schedules theirs again."""
        self.waiting = [e for e in self.waiting if e[0] < written]
