"""The model watched in every job: the servo model run on the frames sent, against the encoder.

Each axis's eq. 27 model (controller/servo/model.py) is driven by the card's step counter frame
by frame, exactly as the sim card drives its plant, and gives where the tool should be; the
believed encoder rows are compared with it. Where the machine is its model the residual is the
encoder's quantisation; where it has drifted (a worn axis, a retuned drive, another load) the
residual grows, and the result says so and recommends `cncctl identify` (a warning, never a
fault: the following-error check stops what is dangerous).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller.config import MachineConfig
from controller.motion.checks import BATCH_ROWS, RefHistory
from controller.servo.model import contour_error_mm, discretise
from controller.servo.stacked import StackedFilter


class ModelWatch:
    """Running max/RMS of measured minus modelled position, per axis and normal to the path
    (eq. 28's direction, as contour_error_mm); BATCH_ROWS rows at a time, every axis's filter
    in one call over the frames between two batches."""

    def __init__(self, config: MachineConfig, start_counts: np.ndarray,
                 batch_rows: int | None = None) -> None:
        self.names = config.axis_names
        self.batch_rows = batch_rows  # None: BATCH_ROWS (virtual time: checks.py says why)
        self.period_s = config.sample_period_s
        self.pulse_mm = np.array([a.pulse_mm for a in config.axes])
        self.servos = [discretise(a.servo, self.period_s) for a in config.axes]
        # The job starts at rest: the models' states are zero there.
        self.models = StackedFilter(self.servos)
        self.prev_counts = np.asarray(start_counts, dtype=np.int64).copy()
        self.next_seq = 0  # the first frame the models have not run yet
        self.limit_mm = config.interpolator.contour_error_limit_mm
        self.share = config.runtime.model_watch_share
        n = len(self.names)
        self.axis_max_mm = np.zeros(n)
        self.axis_sum_sq_mm2 = np.zeros(n)
        self.axis_n = 0
        self.unmatched = 0  # rows whose step counter is not what was sent after their frame
        self.contour_max_mm = 0.0
        self.contour_sum_sq_mm2 = 0.0
        self.contour_n = 0
        self._seq: list[np.ndarray] = []
        self._cmd: list[np.ndarray] = []
        self._enc: list[np.ndarray] = []
        self._rows = 0
        self._hist: RefHistory | None = None

    def update(self, seq: np.ndarray, commanded_counts: np.ndarray, encoder_counts: np.ndarray,
               hist: RefHistory) -> None:
        """Believed feedback rows after frames seq (increasing, maybe with gaps)."""
        if not len(seq):
            return
        self._hist = hist
        self._seq.append(np.asarray(seq, dtype=np.int64))
        self._cmd.append(np.asarray(commanded_counts))
        self._enc.append(np.asarray(encoder_counts))
        self._rows += len(seq)
        if self._rows >= (self.batch_rows or BATCH_ROWS):
            self._measure()

    def _measure(self) -> None:
        hist = self._hist
        if not self._rows or hist is None:
            return
        seq, cmd, enc = (np.concatenate(r) for r in (self._seq, self._cmd, self._enc))
        self._seq, self._cmd, self._enc, self._rows = [], [], [], 0
        oldest = max(0, hist.count - hist.capacity)
        if self.next_seq < oldest:  # frames gone from the ring (never at the ring's size):
            self.next_seq = oldest  # the models go on from there rather than stop
        # Rows of frames the models have run, or not sent (a drive numbering its rows
        # otherwise), are left out.
        keep = (seq >= self.next_seq) & (seq < hist.count)
        self.unmatched += int(len(seq) - keep.sum())
        seq, cmd, enc = seq[keep], cmd[keep], enc[keep]
        if not len(seq):
            return
        frames = np.arange(self.next_seq, int(seq[-1]) + 1)
        counts = hist.cmd_counts[frames % hist.capacity]
        # A row is compared only where the drive's step counter is what was sent after its
        # frame: a drive numbering its rows otherwise would read as a model gone wrong.
        matched = (cmd == counts[seq - frames[0]]).all(axis=1)
        self.unmatched += int(len(seq) - matched.sum())
        v_mm_s = np.diff(np.vstack([self.prev_counts, counts]), axis=0) * (
            self.pulse_mm / self.period_s)
        model_mm = counts * self.pulse_mm - self.models.step(v_mm_s)
        self.prev_counts, self.next_seq = counts[-1].copy(), int(frames[-1]) + 1
        seq, enc = seq[matched], enc[matched]
        if not len(seq):
            return
        res = enc * self.pulse_mm - model_mm[seq - frames[0]]
        self.axis_max_mm = np.maximum(self.axis_max_mm, np.abs(res).max(axis=0))
        self.axis_sum_sq_mm2 += np.square(res).sum(axis=0)
        self.axis_n += len(res)
        if res.shape[1] < 2:
            return
        # Normal to the path where it moves (the tangent is NaN at rest: not measured there).
        normal = contour_error_mm(res[:, 0], res[:, 1], hist.phi_rad[seq % hist.capacity])
        normal = np.abs(normal[np.isfinite(normal)])
        if normal.size:
            self.contour_max_mm = max(self.contour_max_mm, float(normal.max()))
            self.contour_sum_sq_mm2 += float(np.square(normal).sum())
            self.contour_n += int(normal.size)

    def summary_um(self) -> dict[str, Any]:
        """{max, rms (normal to the path), samples, unmatched, axes: {name: {max, rms}}},
        in um (samples: rows compared; unmatched: rows left out, see _measure)."""
        self._measure()  # the rows since the last batch
        axis_rms = np.sqrt(self.axis_sum_sq_mm2 / max(1, self.axis_n))
        return {
            "max": round(self.contour_max_mm * 1e3, 3),
            "rms": round(float(np.sqrt(self.contour_sum_sq_mm2 / max(1, self.contour_n))) * 1e3,
                         3),
            "samples": self.axis_n,
            "unmatched": self.unmatched,
            "axes": {n: {"max": round(float(m) * 1e3, 3), "rms": round(float(r) * 1e3, 3)}
                     for n, m, r in zip(self.names, self.axis_max_mm, axis_rms, strict=True)},
        }

    def warning(self, residual_um: dict[str, Any]) -> str | None:
        """A sentence with the figure where the contour residual exceeds the share of the
        contour limit, or None."""
        limit_um = self.limit_mm * 1e3
        worst_um = float(residual_um["max"])
        if worst_um <= self.share * limit_um:
            return None
        return (f"the servo model no longer holds: the measured contour differs from the "
                f"model's prediction by up to {worst_um:.1f} um ({worst_um / limit_um:.0%} of "
                f"the {limit_um:g} um contour limit, warned above {self.share:.0%}); run "
                "`cncctl identify` to measure the axes again")
