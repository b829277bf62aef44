"""The motion controller's result: outcome, figures and where the machine ended, read back."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller.motion.types import MotionResult, Outcome
from drivers.errors import LostCommunicationError


def _read_position(ctrl: Any) -> tuple[np.ndarray | None, np.ndarray, bool]:
    """(card step counter or None, encoder counts, known?) -- last known if the card is mute."""
    try:
        cmd, enc = ctrl.drive.position_counts()
        return cmd, enc, True
    except LostCommunicationError:
        return None, ctrl.last_enc, False


def build_result(ctrl: Any) -> MotionResult:
    names = ctrl.config.axis_names
    cmd, enc, known = _read_position(ctrl)
    commanded = ctrl.pulses.commanded_counts
    executed = (cmd - ctrl.start_cmd) if cmd is not None else np.full(len(names), -1)
    motion_s = 0.0 if ctrl.first_motion_s is None else ctrl.last_motion_s - ctrl.first_motion_s
    min_fifo_ms = (ctrl.min_fifo_frames or 0) * ctrl.period_s * 1e3
    return MotionResult(
        outcome=ctrl.outcome or Outcome.DONE,
        message=ctrl.message,
        line=ctrl.line,
        motion_time_s=motion_s + (ctrl.period_s if ctrl.first_motion_s is not None else 0.0),
        planned_time_s=ctrl.sent * ctrl.period_s,
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
    )
