"""The figures of `cncctl simulate` (Table IV's rows and more), accumulated sample block by block.

Maxima and the worst place are exact on any length. Sums (RMS, mean) are numpy's over the
whole array, bit for bit, as long as the program has at most EXACT_SUM_SAMPLES samples (the
values are kept until then); beyond, they are summed block by block with compensation, which
agrees to about 1e-15 relative but not to the last bit."""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.generator.replan import RunPlan, RunStatus
from controller.runtime.simulate_stream import SampleBlock

EXACT_SUM_SAMPLES = 1 << 18  # about 4 minutes of motion at 1 ms: 8 MB of kept values


class Moments:
    """Max, mean and RMS of values given in parts: exact (numpy on the whole array) while the
    parts hold at most `exact_limit` values, then running compensated sums."""

    def __init__(self, exact_limit: int = EXACT_SUM_SAMPLES) -> None:
        self.exact_limit = exact_limit
        self.parts: list[np.ndarray] | None = []
        self.count = 0
        self.peak = -math.inf
        self._sums = [[0.0, 0.0], [0.0, 0.0]]  # (sum, compensation) of a and of a * a

    def add(self, a: np.ndarray) -> None:
        if a.size == 0:
            return
        self.count += a.size
        self.peak = max(self.peak, float(a.max()))
        if self.parts is not None:
            self.parts.append(a)
            if self.count <= self.exact_limit:
                return
            kept, self.parts = self.parts, None
            for part in kept:
                self._fold(part)
            return
        self._fold(a)

    def _fold(self, a: np.ndarray) -> None:
        for acc, value in zip(self._sums, (float(np.sum(a)), float(np.sum(a * a))), strict=True):
            total = acc[0] + value  # Neumaier's compensated sum
            if abs(acc[0]) >= abs(value):
                acc[1] += (acc[0] - total) + value
            else:
                acc[1] += (value - total) + acc[0]
            acc[0] = total

    def stats(self) -> dict[str, float]:
        """max, rms, mean (all 0 without values), as _stats_um of the whole array."""
        if self.count == 0:
            return {"max": 0.0, "rms": 0.0, "mean": 0.0}
        if self.parts is not None:
            a = np.concatenate(self.parts) if len(self.parts) > 1 else self.parts[0]
            return {"max": float(a.max()), "rms": float(np.sqrt(np.mean(a * a))),
                    "mean": float(a.mean())}
        total, squares = (s + c for s, c in self._sums)
        return {"max": self.peak, "rms": math.sqrt(squares / self.count),
                "mean": total / self.count}


@dataclass(eq=False)
class RunSummary:
    """What the report needs from the runs' plans (the plans themselves are not kept)."""

    corners: int = 0
    ph_segments: int = 0
    fit_max_mm: list[float] = field(default_factory=list)
    fit_rms2: array = field(default_factory=lambda: array("d"))
    rounds: int = 0
    all_ok: bool = True
    count: int = 0  # runs and look-ahead windows planned
    rounds_total: int = 0

    def add(self, run: RunPlan) -> None:
        self.count += 1
        self.rounds_total += run.dynamics_rounds
        self.corners += len(run.corners)
        self.ph_segments += len(run.geometry.ph_pieces)
        for c in run.corners:
            if c.ph_count:
                self.fit_max_mm.append(c.fit_max_mm)
                self.fit_rms2.append(c.fit_rms_mm ** 2)
        if len(self.fit_max_mm) > 1:
            self.fit_max_mm[:] = [max(self.fit_max_mm)]
        self.rounds = max(self.rounds, run.dynamics_rounds)
        self.all_ok = self.all_ok and run.status == RunStatus.OK

    def stats(self) -> dict[str, float | int]:
        """`cncctl simulate --stats`: how the plan was obtained (not a figure of the plan)."""
        return {"windows": self.count, "dynamics_rounds_total": self.rounds_total,
                "dynamics_rounds_mean": self.rounds_total / self.count if self.count else 0.0,
                "dynamics_rounds_max": self.rounds}

    def ph_fit_um(self) -> dict[str, float]:
        if not self.fit_rms2:
            return {"max": 0.0, "rms": 0.0}
        return {"max": max(self.fit_max_mm) * 1000.0,
                "rms": float(np.sqrt(np.mean(np.frombuffer(self.fit_rms2)))) * 1000.0}


class Figures:
    """Every figure of report() from the stream of finished sample blocks."""

    def __init__(self, n_axes: int, sample_period_s: float,
                 exact_limit: int = EXACT_SUM_SAMPLES) -> None:
        self.T = sample_period_s  # noqa: N815
        self.x, self.y = Moments(exact_limit), Moments(exact_limit)
        self.contour, self.true = Moments(exact_limit), Moments(exact_limit)
        self.n_ref = 0
        self.n_all = 0
        self.last_row = np.zeros((1, n_axes))  # the reference before the next sample
        self.last_step: float | None = None
        self.max_feed = 0.0
        self.max_accel = 0.0
        self.true_max = 0.0  # the first largest true error over contouring samples ...
        self.true_at: dict[str, Any] | None = None  # ... and where it is
        self.runs = RunSummary()

    def add(self, b: SampleBlock) -> None:
        m = len(b)
        if m == 0:
            return
        self.x.add(np.abs(b.ex_mm) * 1000.0)
        self.y.add(np.abs(b.ey_mm) * 1000.0)
        self.contour.add(np.abs(b.contour_mm[b.contouring]) * 1000.0)
        self.true.add(b.true_mm[b.contouring] * 1000.0)
        self._worst(b)
        if b.n_ref:
            self._feed(b.ref_mm[:b.n_ref])
        self.n_ref += b.n_ref
        self.n_all += m

    def _worst(self, b: SampleBlock) -> None:
        e = np.where(b.contouring, b.true_mm, 0.0)
        k = int(np.argmax(e))
        if self.true_at is not None and not e[k] > self.true_max:
            return
        g = b.i0 + k
        row = b.ref_mm[k]
        self.true_max = float(e[k])
        self.true_at = {"t_s": round((g + 1) * self.T, 6), "line": int(b.line[k]),
                        "x_mm": round(float(row[0] - b.ex_mm[k]), 6),
                        "y_mm": round(float(row[1] - b.ey_mm[k]), 6),
                        "after_end": k >= b.n_ref}

    def _feed(self, ref: np.ndarray) -> None:
        """Feed and tangential acceleration from finite differences of the reference."""
        steps = np.linalg.norm(np.diff(np.vstack([self.last_row, ref]), axis=0), axis=1) / self.T
        self.last_row = ref[-1:]
        self.max_feed = max(self.max_feed, float(steps.max()))
        if self.last_step is not None:
            steps = np.r_[self.last_step, steps]
        if steps.size > 1:
            self.max_accel = max(self.max_accel, float(np.abs(np.diff(steps) / self.T).max()))
        self.last_step = float(steps[-1])

    def report(self, program: str, algorithm: str, limit_um: float,
               planning_cpu_s: float) -> dict:
        """The JSON object of `cncctl simulate --json`."""
        x, y = self.x.stats(), self.y.stats()
        true_max = self.true_max * 1000.0
        true = {"max": true_max, "rms": self.true.stats()["rms"], "at": self.true_at}
        return {
            "program": program,
            "algorithm": algorithm,
            "motion_time_s": float(self.n_ref * self.T),
            "samples": int(self.n_ref),
            "sample_period_s": self.T,
            "tracking_error_um": {"x": {"max": x["max"], "rms": x["rms"]},
                                  "y": {"max": y["max"], "rms": y["rms"]}},
            "contour_error_um": self.contour.stats(),
            "contour_error_true_um": true,
            "max_feed_mm_s": self.max_feed,
            "max_tangential_accel_mm_s2": self.max_accel,
            "sharp_corners": self.runs.corners,
            "ph_segments": self.runs.ph_segments,
            "ph_fit_error_um": self.runs.ph_fit_um(),
            "dynamics_rounds": self.runs.rounds,
            # The limit is on the tool's distance from the path (eq. 28 stays, for Table IV).
            "contour_limit_met": self.runs.all_ok and true_max <= limit_um + 1e-9,
            "planning_cpu_s": planning_cpu_s,
        }
