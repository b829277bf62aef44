"""The motion loop pre-compensates what it sends: measured on the sim card, with holds and stops."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from runtime_helpers import Recorder, virtual_card, xy_config

from controller.generator.plan import generate_reference
from controller.interpreter.program import read_program
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.source import ChunkSource
from controller.motion.types import MotionProgress, MotionSettings, MotionState, Outcome
from controller.servo.path_distance import PathDistance, path_polyline

PLAIN = xy_config()
ON = replace(PLAIN, interpolator=replace(PLAIN.interpolator, servo_precompensation=True))
T = ON.sample_period_s
LIMIT_UM = ON.interpolator.contour_error_limit_mm * 1e3
BUTTERFLY = Path(__file__).resolve().parents[2] / "nc_programs" / "butterfly.nc"


@cache
def chunks() -> tuple:
    return tuple(generate_reference(read_program(str(BUTTERFLY), ON), ON))


@cache
def path() -> PathDistance:
    return PathDistance(path_polyline(list(read_program(str(BUTTERFLY), ON))))


def run(hold_at_s: float | None = None, abort_at_s: float | None = None,
        high_water_ms: float | None = None
        ) -> tuple[object, np.ndarray, np.ndarray, list[MotionProgress]]:
    """Run in virtual time; returns the result, the commanded and encoder positions of every
    executed frame (mm) and the progress reports."""
    card = virtual_card(ON)
    rec = Recorder(card)
    settings = MotionSettings.from_config(ON, progress_every_s=0.002)
    if high_water_ms is not None:
        settings = replace(settings, high_water_ms=high_water_ms, low_water_ms=10.0)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    seen: list[MotionProgress] = []
    asked = {"hold": False, "abort": False}

    def progress(p: MotionProgress) -> None:
        seen.append(p)
        if hold_at_s is not None and not asked["hold"] and p.executed_s >= hold_at_s:
            asked["hold"] = True
            ctrl.request_hold()
        if p.state is MotionState.HELD and sum(s.state is MotionState.HELD for s in seen) == 20:
            ctrl.request_resume()
        if abort_at_s is not None and not asked["abort"] and p.executed_s >= abort_at_s:
            asked["abort"] = True
            ctrl.request_abort("test abort")

    ctrl = MotionController(ON, card, ChunkSource(chunks()), pacer, settings,
                            on_progress=progress)
    result = ctrl.run()
    parts = [p for p in rec.parts if len(p)]
    pulse = np.array([a.pulse_mm for a in ON.axes])
    cmd = np.concatenate([p.commanded_counts for p in parts]) * pulse
    enc = np.concatenate([p.encoder_counts for p in parts]) * pulse
    return result, cmd, enc, seen


def test_run_leads_the_path_and_the_tool_stays_on_it() -> None:
    result, cmd, enc, _ = run()
    assert result.outcome is Outcome.DONE and result.underruns == 0, result.message
    assert result.contour_error_um["max"] <= LIMIT_UM
    # The frames sent are not the path (they lead it by up to tens of um), the tool is.
    assert path().measure(cmd).distance_mm.max() > 0.04
    assert path().measure(enc).distance_mm.max() * 1e3 <= LIMIT_UM
    end = chunks()[-1].pos_mm[-1, :2]
    final = np.array([result.final_position_mm["x"], result.final_position_mm["y"]])
    assert np.abs(final - end).max() <= 1e-3
    assert np.allclose(enc[-1], end, atol=1.5e-3) and np.allclose(cmd[-1], end, atol=1.5e-3)


@pytest.mark.parametrize("hold_at_s", [0.9, 3.1, 5.2])
def test_hold_and_resume_compensated_stay_on_the_path(hold_at_s: float) -> None:
    result, cmd, enc, seen = run(hold_at_s=hold_at_s)
    assert result.outcome is Outcome.DONE, result.message
    assert any(s.state is MotionState.HELD for s in seen)
    assert result.contour_error_um["max"] <= LIMIT_UM
    assert path().measure(enc).distance_mm.max() * 1e3 <= LIMIT_UM
    held = [s for s in seen if s.state is MotionState.HELD]
    p = np.array(held[-1].position_mm)[None, :2]
    assert path().measure(p).distance_mm.max() <= 2e-3  # at rest on the path, lead gone


def test_abort_stops_along_the_path_with_the_lead_gone() -> None:
    result, cmd, enc, _ = run(abort_at_s=2.0)
    assert result.outcome is Outcome.ABORTED
    assert path().measure(enc).distance_mm.max() * 1e3 <= LIMIT_UM
    assert np.abs(cmd[-1] - enc[-1]).max() <= 1e-3  # settled where it was sent
    assert path().measure(cmd[-1:]).distance_mm.max() <= 2e-3


def test_the_settling_frames_keep_the_high_water_mark() -> None:
    """The lead's settling at the end (80 frames on Table II) goes out as the card drains,
    not at once past the high-water mark (a small FIFO would overflow)."""
    result, cmd, enc, seen = run(high_water_ms=30.0)
    assert result.outcome is Outcome.DONE and result.underruns == 0, result.message
    assert max(p.fifo_ms for p in seen) <= 30.0
    end = chunks()[-1].pos_mm[-1, :2]
    assert np.allclose(cmd[-1], end, atol=1.5e-3)
    assert result.contour_error_um["max"] <= LIMIT_UM
