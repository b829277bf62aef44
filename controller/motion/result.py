"""The motion controller's reports: its progress while it runs, and its result (outcome, figures
and where the machine ended, read back)."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller.motion.types import MotionProgress, MotionResult, Outcome
from drivers.errors import LostCommunicationError


def _read_position(ctrl: Any) -> tuple[np.ndarray | None, np.ndarray, bool]:
    """(card step counter or None, encoder counts, known?) -- last known if the card is mute."""
    try:
        cmd, enc = ctrl.drive.position_counts()
    except LostCommunicationError:
        return None, ctrl.last_enc, False
    if ctrl.fbcheck.corrupt:  # the drive's reading is what was not believed: the last one was
        return cmd, ctrl.last_enc, False
    return cmd, enc, True


def build_result(ctrl: Any) -> MotionResult:
    names = ctrl.config.axis_names
    cmd, enc, known = _read_position(ctrl)
    commanded = ctrl.pulses.commanded_counts
    executed = (cmd - ctrl.start_cmd) if cmd is not None else np.full(len(names), -1)
    # From the first frame to the last one fed back; the motion time proper ends where the
    # tool came within the in-position tolerance of the end, the rest is settling.
    total_s = (0.0 if ctrl.first_motion_s is None
               else ctrl.last_motion_s - ctrl.first_motion_s + ctrl.period_s)
    motion_s = ctrl.in_position.motion_s(ctrl.executed, total_s) if ctrl.executed else 0.0
    if ctrl.first_motion_s is not None and ctrl.settled_since_s is not None:
        # the servo settled to the last count after the last frame ran (the paper's method)
        total_s = max(total_s, ctrl.settled_since_s - ctrl.first_motion_s + ctrl.period_s)
    min_fifo_ms = (ctrl.min_fifo_frames or 0) * ctrl.period_s * 1e3
    return MotionResult(
        outcome=ctrl.outcome or Outcome.DONE,
        message=ctrl.message,
        line=ctrl.line,
        motion_time_s=motion_s,
        planned_time_s=(ctrl.sent - ctrl.lead_frames) * ctrl.period_s,
        contour_error_um=ctrl.contour.summary_um(),
        following_error_um_max=ctrl.ferr.max_abs_mm * 1e3,
        underruns=ctrl.underruns,
        late_cycles=ctrl.pacer.late_cycles,
        min_fifo_ms=min_fifo_ms,
        commanded_counts={n: int(c) for n, c in zip(names, commanded, strict=True)},
        executed_counts={n: int(c) for n, c in zip(names, executed, strict=True)},
        final_position_mm={n: float(e * p) for n, e, p in
                           zip(names, enc, ctrl.pulse_mm, strict=True)},
        position_known=known,
        time_to_first_motion_s=ctrl.first_motion_s,
        settling_time_s=max(0.0, total_s - motion_s),
    )


def build_progress(ctrl: Any, level: int, now_s: float) -> MotionProgress:
    """Where the run is: state, line, feed, following error, card FIFO (level frames), time."""
    total = ctrl.source.total_rows()
    idx = (ctrl.executed - 1) % ctrl.hist.capacity
    return MotionProgress(
        state=ctrl.state, line=ctrl.line,
        feed_mm_s=float(ctrl.hist.feed_mm_s[idx]) if ctrl.executed else 0.0,
        ferror_um=float(np.abs(ctrl.ferr.last_mm).max()) * 1e3,
        fifo_ms=level * ctrl.period_s * 1e3, elapsed_s=now_s,
        executed_s=ctrl.executed * ctrl.period_s,
        planned_s=None if total is None else total * ctrl.period_s,
        override_pct=ctrl.override_pct,
        position_mm=tuple(float(v) for v in ctrl.last_enc * ctrl.pulse_mm),
        work_origin_mm=ctrl.work_origin_mm)
