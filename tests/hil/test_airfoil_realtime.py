"""HIL: nc_programs/naca2415.nc through the three processes in real time (1 kHz, sim card)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from controller.config import load_config
from controller.motion.types import Outcome
from controller.runtime.processes import Runtime, RuntimeOptions
from controller.servo.model import contour_error_mm, discretise, tracking_error_mm

PROGRAM = Path(__file__).resolve().parents[2] / "nc_programs" / "naca2415.nc"

pytestmark = [pytest.mark.hil]


def planned_reference(config: object) -> np.ndarray:
    """The reference the generator streams, computed offline in this process."""
    from controller.generator.plan import generate_reference
    from controller.interpreter.program import read_program

    chunks = list(generate_reference(read_program(str(PROGRAM), config), config))
    assert chunks[-1].final
    return np.vstack([c.pos_mm for c in chunks])


def predicted_contour_um(pos_mm: np.ndarray, config: object) -> tuple[float, float]:
    """Eq. 28 over the servo model driven by the whole reference (what `simulate` predicts)."""
    t = config.sample_period_s  # type: ignore[attr-defined]
    v = np.diff(pos_mm, axis=0, prepend=pos_mm[:1]) / t
    e = np.column_stack([tracking_error_mm(discretise(a.servo, t), v[:, i])
                         for i, a in enumerate(config.axes)])  # type: ignore[attr-defined]
    moving = np.hypot(v[:, 0], v[:, 1]) >= 0.05
    eps = np.abs(contour_error_mm(e[:, 0], e[:, 1], np.arctan2(v[:, 1], v[:, 0])))[moving]
    return float(eps.max() * 1e3), float(np.sqrt(np.mean(eps ** 2)) * 1e3)


def test_airfoil_runs_in_real_time_on_the_sim_card() -> None:
    config = load_config("xy_table_paper")
    ref = planned_reference(config)
    planned_s = len(ref) * config.sample_period_s
    assert planned_s < 8.0, "the HIL run must stay under 10 s"
    result = Runtime(str(PROGRAM), config, RuntimeOptions(virtual_time=False)).run()
    assert result.outcome is Outcome.DONE, result.message
    assert result.underruns == 0
    end_counts = np.rint(ref[-1] / [a.pulse_mm for a in config.axes]).astype(int)
    final_counts = [round(result.final_position_mm[a.name] / a.pulse_mm) for a in config.axes]
    assert final_counts == end_counts.tolist()  # exact to the pulse
    assert result.commanded_counts == result.executed_counts
    max_um, rms_um = predicted_contour_um(ref, config)
    assert result.contour_error_um["max"] == pytest.approx(max_um, rel=0.10, abs=2.0)
    assert result.contour_error_um["rms"] == pytest.approx(rms_um, rel=0.10, abs=2.0)
    assert result.motion_time_s == pytest.approx(planned_s, rel=0.05)
