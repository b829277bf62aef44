"""When the tool came within the in-position tolerance of the end: motion time and settling."""

from __future__ import annotations

import numpy as np


class InPosition:
    """Tracks the first executed frame from which the encoder stays within tolerance_mm of the
    newest commanded end point (the last count sent).

    Before the last frames are sent that point runs ahead of the tool, so every frame the tool
    spends moving is outside it; at a standstill in mid-program (a pause, a dwell) the tool may
    be inside it for a while, and the motion after it makes it leave again. What is left at the
    end is the frame from which the tool stayed at its final position: the motion time ends
    there, and the frames after it (the pre-compensation's lead dying away, the servo's last
    micrometres) are the settling."""

    def __init__(self, pulse_mm: np.ndarray, tolerance_mm: float, period_s: float) -> None:
        self.pulse_mm, self.tolerance_mm, self.period_s = pulse_mm, tolerance_mm, period_s
        self.frame: int | None = None  # first frame of the current streak within tolerance
        self.after_frames_s: float | None = None  # reached after the last frame (settle wait)

    def _outside(self, encoder_counts: np.ndarray, target_counts: np.ndarray) -> np.ndarray:
        off_mm = (encoder_counts - target_counts) * self.pulse_mm
        return np.sqrt((off_mm * off_mm).sum(axis=-1)) > self.tolerance_mm + 1e-12

    def frames(self, seq: np.ndarray, encoder_counts: np.ndarray,
               target_counts: np.ndarray) -> None:
        """Executed frames (their numbers from 0 and encoder counts) against the end sent."""
        if not len(seq):
            return
        out = self._outside(encoder_counts, target_counts)
        if out[-1]:  # (moving, the end runs ahead: every row is outside)
            self.frame, self.after_frames_s = None, None
            return
        outside = np.flatnonzero(out)
        if outside.size:
            last = int(outside[-1])
            self.frame = int(seq[last]) + 1 if last + 1 < len(seq) else None
            self.after_frames_s = None
        elif self.frame is None:
            self.frame = int(seq[0])

    def at_rest(self, encoder_counts: np.ndarray, target_counts: np.ndarray,
                since_first_s: float) -> None:
        """A position read while settling (no frames run): the tool may come in only now."""
        if self._outside(encoder_counts, target_counts):
            self.frame, self.after_frames_s = None, None
        elif self.frame is None and self.after_frames_s is None:
            self.after_frames_s = since_first_s

    def motion_s(self, executed_frames: int, fallback_s: float) -> float:
        """From the first frame to in position; fallback_s (the time to the last frame) when
        the tool never came within tolerance before the run ended."""
        if self.frame is not None:
            return min(self.frame + 1, executed_frames) * self.period_s  # frame k ends at (k+1) T
        if self.after_frames_s is not None:
            return max(self.after_frames_s, fallback_s)
        return fallback_s
