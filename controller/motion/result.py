"""The motion controller's result: the figures it counts as it runs (RunFigures), its
supervision (RunChecks), and the result built from them and the position read back."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from controller.motion.checks import ContourStats, FerrorCheck
from controller.motion.feedback_check import FeedbackCheck
from controller.motion.in_position import InPosition
from controller.motion.model_watch import ModelWatch
from controller.motion.types import MotionResult, Outcome
from drivers.base import Drive
from drivers.errors import LostCommunicationError


@dataclass
class RunFigures:
    """What a run's progress and result report, counted by the loop as it goes."""

    start_cmd: np.ndarray  # the card's step counter when the run started (counts)
    last_enc: np.ndarray  # the last encoder reading believed (counts)
    line: int = 0  # the program line of the last frame fed back
    executed: int = 0  # frames fed back as run
    underruns: int = 0
    min_fifo_frames: int | None = None  # the card FIFO's lowest level while running
    first_motion_s: float | None = None  # pacer time of the first frame fed back
    last_motion_s: float = 0.0  # ... and of the last one
    settled_since_s: float | None = None  # step counter and encoder equal since then
    lead_frames: int = 0  # frames of the pre-compensation's lead dying away (not planned)


@dataclass
class RunChecks:
    """The run's supervision, each part keeping the figures it reports."""

    ferr: FerrorCheck
    fbcheck: FeedbackCheck
    contour: ContourStats
    in_position: InPosition
    model: ModelWatch

    @classmethod
    def start(cls, config: MachineConfig, start_cmd: np.ndarray, start_enc: np.ndarray,
              in_position_mm: float, batch_rows: int | None = None) -> RunChecks:
        """A run's checks from where the card stands; batch_rows: the statistics' batches
        (None: BATCH_ROWS; virtual time: larger, see checks.py)."""
        pulse_mm = np.array([a.pulse_mm for a in config.axes])
        return cls(
            ferr=FerrorCheck(config, start_cmd),
            fbcheck=FeedbackCheck(config, start_enc),
            contour=ContourStats(pulse_mm, batch_rows),
            model=ModelWatch(config, start_cmd, batch_rows),
            in_position=InPosition(pulse_mm, in_position_mm, config.sample_period_s),
        )


def read_position(drive: Drive, fbcheck: FeedbackCheck,
                  last_enc: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, bool]:
    """(card step counter or None, encoder counts, known?) -- last known if the card is mute."""
    try:
        cmd, enc = drive.position_counts()
    except LostCommunicationError:
        return None, last_enc, False
    if fbcheck.corrupt:  # the drive's reading is what was not believed: the last one was
        return cmd, last_enc, False
    return cmd, enc, True


def build_result(config: MachineConfig, figures: RunFigures, checks: RunChecks,
                 outcome: Outcome | None, message: str, commanded: np.ndarray,
                 sent_frames: int, late_cycles: int, drive: Drive) -> MotionResult:
    """The run's result: outcome, figures, and where the machine ended (read back now)."""
    names = config.axis_names
    period_s = config.sample_period_s
    pulse_mm = [a.pulse_mm for a in config.axes]
    f = figures
    cmd, enc, known = read_position(drive, checks.fbcheck, f.last_enc)
    executed = (cmd - f.start_cmd) if cmd is not None else np.full(len(names), -1)
    # From the first frame to the last one fed back; the motion time proper ends where the
    # tool came within the in-position tolerance of the end, the rest is settling.
    total_s = (0.0 if f.first_motion_s is None
               else f.last_motion_s - f.first_motion_s + period_s)
    motion_s = checks.in_position.motion_s(f.executed, total_s) if f.executed else 0.0
    if f.first_motion_s is not None and f.settled_since_s is not None:
        # the servo settled to the last count after the last frame ran (the paper's method)
        total_s = max(total_s, f.settled_since_s - f.first_motion_s + period_s)
    min_fifo_ms = (f.min_fifo_frames or 0) * period_s * 1e3
    residual_um = checks.model.summary_um()
    return MotionResult(
        outcome=outcome or Outcome.DONE,
        message=message,
        line=f.line,
        motion_time_s=motion_s,
        planned_time_s=(sent_frames - f.lead_frames) * period_s,
        contour_error_um=checks.contour.summary_um(),
        following_error_um_max=checks.ferr.max_abs_mm * 1e3,
        underruns=f.underruns,
        late_cycles=late_cycles,
        min_fifo_ms=min_fifo_ms,
        commanded_counts={n: int(c) for n, c in zip(names, commanded, strict=True)},
        executed_counts={n: int(c) for n, c in zip(names, executed, strict=True)},
        final_position_mm={n: float(e * p) for n, e, p in
                           zip(names, enc, pulse_mm, strict=True)},
        position_known=known,
        time_to_first_motion_s=f.first_motion_s,
        settling_time_s=max(0.0, total_s - motion_s),
        model_residual_um=residual_um,
        model_warning=checks.model.warning(residual_um),
    )
