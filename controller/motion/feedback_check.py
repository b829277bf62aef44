"""Feedback a drive could not have given: an encoder jump or a position off the travel."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from drivers.base import Feedback

# An axis overshoots its commanded speed while it catches up with a step of the reference;
# twice its maximum velocity in one period, plus two pulses of quantisation, is more than any
# axis of the config can move. (A bit flip on the slcan link read 8388.608 mm in one period.)
JUMP_SPEED_FACTOR = 2.0
JUMP_SLACK_PULSES = 2


@dataclass(frozen=True)
class ImplausibleFeedback:
    axis: str
    message: str
    seq: int


class FeedbackCheck:
    """Per frame and axis: the encoder moves at most what the axis can move in one period, and
    stays within the travel widened by the axis's following-error limit at full speed."""

    def __init__(self, config: MachineConfig, start_counts: np.ndarray) -> None:
        self.names = config.axis_names
        self.pulse_mm = np.array([a.pulse_mm for a in config.axes])
        vmax_mm_s = np.array([a.max_velocity_mm_s for a in config.axes])
        self.max_step_counts = (JUMP_SPEED_FACTOR * vmax_mm_s * config.sample_period_s
                                / self.pulse_mm + JUMP_SLACK_PULSES)
        slack_mm = np.array([max(a.ferror_mm, a.min_ferror_mm) for a in config.axes])
        travel = np.array([a.travel_mm for a in config.axes])
        # A halted card's frame counter stops while its motors still close their following
        # error: rows it reports then may move that much more than the frames say.
        self.settle_counts = slack_mm / self.pulse_mm
        self.lo_counts = (travel[:, 0] - slack_mm) / self.pulse_mm
        self.hi_counts = (travel[:, 1] + slack_mm) / self.pulse_mm
        self.last = np.asarray(start_counts, dtype=np.int64).copy()
        self.corrupt = False
        self.last_seq = -1  # the start counts stand before the run's first frame (seq 0)

    def believed(self, fb: Feedback, settling: bool = False
                 ) -> tuple[Feedback, ImplausibleFeedback | None]:
        """The rows before the first implausible one, and what was wrong with it; after one,
        no row is believed (a drive that read garbage once cannot be trusted on). settling:
        the card has halted (its motors may still move by their following error)."""
        if self.corrupt:
            return _rows(fb, 0), None
        bad = self.check(fb, settling)
        if bad is None:
            return fb, None
        self.corrupt = True
        return _rows(fb, int(np.searchsorted(fb.seq, bad.seq))), bad

    def check(self, fb: Feedback, settling: bool = False) -> ImplausibleFeedback | None:
        if not len(fb):
            return None
        enc = fb.encoder_counts
        # (Slices and ufuncs: np.diff and np.vstack cost more than the check on a cycle's rows.)
        step = np.abs(enc - np.concatenate((self.last[None, :], enc[:-1])))
        # Rows may be frames apart (the serial card reports every few frames): the allowance
        # grows with the frames between two readings.
        seq = np.asarray(fb.seq, dtype=np.int64)
        if len(seq) <= 2 and int(seq[0]) == self.last_seq + 1 \
                and int(seq[-1]) == self.last_seq + len(seq):
            frames = _ONE  # a cycle's rows a frame each: the same allowance, fewer calls
        else:
            prev = np.empty_like(seq)  # (a tuple joined to seq[:-1] converted it first)
            prev[0], prev[1:] = self.last_seq, seq[:-1]
            frames = np.maximum(seq - prev, 1)[:, None]
        self.last, self.last_seq = enc[-1].copy(), int(seq[-1])
        mm = self.pulse_mm
        allowed = self.max_step_counts * frames + (self.settle_counts if settling else 0.0)
        jumps = step > allowed
        off = (enc < self.lo_counts) | (enc > self.hi_counts)
        if not (jumps | off).any():
            return None
        if jumps.any():
            row, axis = (int(v) for v in np.argwhere(jumps)[0])
            frames, allowed = np.broadcast_to(frames, (len(seq), 1)), np.broadcast_to(allowed,
                                                                                    step.shape)
            return self._bad(axis, int(seq[row]), (
                f"jumped {step[row, axis] * mm[axis]:.3f} mm in {frames[row, 0]} period(s) (at "
                f"most {allowed[row, axis] * mm[axis]:.3f} mm is possible)"))
        if off.any():
            row, axis = (int(v) for v in np.argwhere(off)[0])
            return self._bad(axis, int(seq[row]), (
                f"reads {enc[row, axis] * mm[axis]:.3f} mm, off its travel "
                f"[{self.lo_counts[axis] * mm[axis]:.3f}, {self.hi_counts[axis] * mm[axis]:.3f}] "
                "mm"))
        return None

    def _bad(self, axis: int, seq: int, what: str) -> ImplausibleFeedback:
        return ImplausibleFeedback(self.names[axis], f"{self.names[axis].upper()} axis encoder "
                                   f"{what}: corrupt feedback; the position is unknown", seq)


_ONE = np.ones((1, 1), dtype=np.int64)


def _rows(fb: Feedback, n: int) -> Feedback:
    return Feedback(fb.seq[:n], fb.commanded_counts[:n], fb.encoder_counts[:n])
