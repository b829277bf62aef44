"""Servo pre-compensation: the residual filter is the compensated loop, and the tool follows."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import ConfigError, load_config, parse_config
from controller.interpreter.program import read_program
from controller.runtime.simulation import simulate
from controller.servo.model import (
    discretise,
    small_s_gains,
    tracking_error_mm,
)
from controller.servo.path_distance import PathDistance, path_polyline
from controller.servo.precompensation import (
    Precompensator,
    compensation_filter,
    residual_servo,
)
from controller.servo.prediction import (
    acceleration_gain_s2,
    axis_servos,
    planning_limit_mm,
    plant_servos,
)

REPO = Path(__file__).resolve().parents[2]
CFG = load_config("xy_table_paper")
ON = replace(CFG, interpolator=replace(CFG.interpolator, servo_precompensation=True))
T = CFG.sample_period_s
SERVO = CFG.axis("x").servo


def smooth_path(seed: int, n: int = 1500) -> np.ndarray:
    """A wanted axis position from rest to rest, as plans are: a sum of quintic smooth steps
    (continuous acceleration) of up to 3 mm over 60-400 ms, up to about 2500 mm/s^2."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * T
    x = np.zeros(n)
    for _ in range(4):
        c, w, a = rng.uniform(0.05, 1.0), rng.uniform(0.06, 0.4), rng.uniform(-3.0, 3.0)
        u = np.clip((t - c) / w, 0.0, 1.0)
        x += a * u**3 * (10 - 15 * u + 6 * u**2)
    return x


def plant_actual(frames_mm: np.ndarray) -> np.ndarray:
    """The plain model's actual position for frames sent from 0 at rest."""
    v = np.diff(np.r_[0.0, frames_mm]) / T
    return frames_mm - tracking_error_mm(discretise(SERVO, T), v)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_residual_filter_is_the_plant_driven_by_the_compensated_reference(seed: int) -> None:
    wanted = smooth_path(seed)
    pc = Precompensator([SERVO], T, np.zeros(1))
    frames = pc.to_rest(wanted[:, None])[:, 0]
    held = np.r_[wanted, np.full(len(frames) - len(wanted), wanted[-1])]
    v = np.diff(np.r_[0.0, held]) / T
    residual = tracking_error_mm(residual_servo(SERVO, T), v)
    assert np.abs((held - plant_actual(frames)) - residual).max() < 1e-5
    # and it is small next to what the plain loop leaves on the same wanted path
    plain = np.abs(held - plant_actual(held)).max()
    assert np.abs(residual).max() < 0.1 * plain


def test_streaming_in_chunks_equals_one_pass_and_state_round_trips() -> None:
    wanted = np.column_stack([smooth_path(1), smooth_path(2)])
    one = Precompensator([SERVO, CFG.axis("y").servo], T, np.zeros(2)).push(wanted)
    pc = Precompensator([SERVO, CFG.axis("y").servo], T, np.zeros(2))
    parts = [pc.push(wanted[:400])]
    saved = pc.state()
    pc.push(wanted[400:900] + 5.0)  # a send later taken back
    pc.restore(saved)
    parts += [pc.push(wanted[400:900]), pc.push(wanted[900:])]
    assert np.allclose(np.vstack(parts), one, atol=1e-12, rtol=0.0)


def test_a_column_without_servo_passes_through() -> None:
    wanted = np.column_stack([smooth_path(3), smooth_path(4)])
    out = Precompensator([SERVO, None], T, np.zeros(2)).push(wanted)
    assert np.array_equal(out[:, 1], wanted[:, 1])
    assert np.abs(out[:, 0] - wanted[:, 0]).max() > 1e-3  # X leads


def test_the_lead_dies_away_at_a_standstill_onto_the_wanted_point() -> None:
    wanted = smooth_path(5)
    moving = np.flatnonzero(np.diff(wanted) != 0.0)
    wanted = wanted[: moving[len(moving) // 2]]  # cut while moving: a stop's last row
    pc = Precompensator([SERVO], T, np.zeros(1))
    pc.push(wanted[:, None])
    tail = pc.settling_rows()[:, 0]
    assert 0 < len(tail) < 200
    assert abs(tail[-1] - wanted[-1]) < 1e-5


def test_residual_has_no_velocity_or_acceleration_gain() -> None:
    c1, c2 = small_s_gains(residual_servo(SERVO, T))
    p1, p2 = small_s_gains(discretise(SERVO, T))
    assert abs(c1) < 1e-6 * p1 and abs(c2) < 1e-6 * p2
    assert compensation_filter(SERVO, T).b[0] != 0.0  # a frame depends on its own sample


def test_generator_predicts_with_the_residual_only_when_asked() -> None:
    assert axis_servos(CFG) == plant_servos(CFG)
    assert axis_servos(ON)[0] is residual_servo(SERVO, T)
    assert acceleration_gain_s2(ON) < 1e-3 * acceleration_gain_s2(CFG)


@pytest.mark.parametrize("program", ["naca2415.nc", "naca2415_loop.nc", "butterfly.nc"])
def test_compensated_plan_keeps_the_true_error_with_the_plant_run_on_its_frames(
        program: str) -> None:
    """Independent of the generator's own prediction: the plain plant is run on the frames the
    motion loop would send, and the tool's distance from the programmed path is measured."""
    blocks = list(read_program(str(REPO / "nc_programs" / program), ON))
    traj = simulate(blocks, ON, "ph-lookahead")
    wanted = traj.ref_mm[:, :2]
    pc = Precompensator([SERVO, CFG.axis("y").servo], T, np.zeros(2))
    frames = pc.to_rest(wanted)
    frames = np.vstack([frames, np.repeat(frames[-1:], 60, axis=0)])
    v = np.diff(np.vstack([np.zeros((1, 2)), frames]), axis=0) / T
    act = frames - np.column_stack([tracking_error_mm(s, v[:, i])
                                    for i, s in enumerate(plant_servos(CFG))])
    true_mm = PathDistance(path_polyline(blocks)).measure(act).distance_mm
    assert true_mm.max() <= planning_limit_mm(CFG)
    assert traj.contour_mm.size and np.abs(traj.contour_mm).max() <= planning_limit_mm(CFG)
    # the plan runs faster than the uncompensated one, which the contour limit holds back
    plain = simulate(blocks, CFG, "ph-lookahead")
    assert len(traj.t_s) < len(plain.t_s)


def test_config_key_is_read_and_refused_where_the_loop_has_position_error() -> None:
    data = yaml.safe_load((REPO / "config" / "xy_table.yaml").read_text())
    data["interpolator"]["servo_precompensation"] = True
    assert parse_config(data, "m.yaml").interpolator.servo_precompensation
    data["axes"]["y"]["servo"]["b0"] = 1.5e9
    with pytest.raises(ConfigError, match="servo_precompensation"):
        parse_config(data, "m.yaml")


def test_the_braking_model_is_not_shared_between_compensated_and_plain_plans() -> None:
    """Both kinds of plan in one process (a bench, cncd with two configs): each stop is braked
    on its own loop's model, whichever was planned first."""
    from controller.generator import replan

    blocks = list(read_program(str(REPO / "nc_programs" / "naca2415.nc"), ON))
    replan._MODELS.clear()
    alone = len(simulate(blocks, ON, "ph-lookahead").t_s)
    replan._MODELS.clear()
    simulate(blocks, CFG, "ph-lookahead")
    assert len(simulate(blocks, ON, "ph-lookahead").t_s) == alone
