"""M62/M63/M67 in the motion loop: outputs set with the next move, without a stop. The rows
read carry a mark on the first sample of that move (controller/motion/source.py); the loop
takes the mark off, and when it writes that sample's frame the change goes with it: a drive
that clocks outputs with its frames (drivers/frame_outputs.py, the sim card) sets it at that
frame, any other drive is told by the loop once that frame is fed back as executed."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller.motion.outputs import OutputRunner
from controller.motion.source import row_lines, sync_marked
from drivers.base import Drive
from drivers.frame_outputs import FrameOutputs


class SyncOutputs:
    """The M62 changes read (by line, in stream order) and those written with a frame."""

    def __init__(self, drive: Drive, outputs: OutputRunner, period_s: float) -> None:
        self.drive, self.outputs, self.period_s = drive, outputs, period_s
        self.pending: list[tuple[int, tuple]] = []  # (line, changes): its frame not yet written
        self.written: list[tuple[int, int, tuple]] = []  # (frame, line, changes): written
        self.problem: str | None = None  # a mark whose changes did not come: a fault

    def take(self, rows: np.ndarray, source: Any) -> np.ndarray:
        """Rows as read: the marks taken off (the rest of the loop sees plain lines), their
        changes noted by line."""
        for k in sync_marked(rows):
            line = int(row_lines(rows[k : k + 1])[0])
            rows[k, -1] = float(line)
            changes = getattr(source, "next_sync_outputs", lambda: None)()
            if changes is None:
                self.problem = (
                    f"the M62/M63/M67 changes of line {line} did not reach the motion process"
                )
            else:
                self.pending.append((line, changes))
        return rows

    def on_write(self, lines: np.ndarray, first_frame: int) -> None:
        """Frames first_frame... were queued with these lines: each pending change goes with
        the first frame of its line (the drive clocks it there, where it can). Frames taken
        back (a feed hold) are written again from first_frame: theirs wait for their line."""
        self._taken_back(first_frame)
        while self.pending:
            line, changes = self.pending[0]
            hit = np.flatnonzero(lines == line)
            if not hit.size:
                return
            k = int(hit[0])
            self.pending.pop(0)
            if isinstance(self.drive, FrameOutputs):
                self.drive.schedule_outputs(changes, len(lines) - 1 - k)
            self.written.append((first_frame + k, line, changes))

    def _taken_back(self, sent: int) -> None:
        while self.written and self.written[-1][0] >= sent:
            _, line, changes = self.written.pop()
            self.pending.insert(0, (line, changes))

    def due(self, executed: int, sent: int) -> str | None:
        """Frames executed so far: the changes of those done are reported (and set, on a drive
        that does not clock them); those on frames taken back wait for their line again."""
        self._taken_back(sent)
        while self.written and self.written[0][0] < executed:
            frame, line, changes = self.written.pop(0)
            t_s = frame * self.period_s
            if isinstance(self.drive, FrameOutputs):
                self.outputs.report(list(changes), t_s, line)
            elif (problem := self.outputs.at_mark(changes, t_s, line)) is not None:
                return problem
        problem, self.problem = self.problem, None
        return problem
