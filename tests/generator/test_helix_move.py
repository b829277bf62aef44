"""Helices and G18/G19 arcs planned as 3-axis motion: the plan ends where programmed, keeps
the feed, every axis's velocity and the path acceleration within their limits, and the modelled
tool within the contour limit of the 3-D path, measured here through the motion loop's own
pre-compensation and each axis's plant, against a dense polyline of the curve."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from helix_helpers import modelled_tool, nearest_mm
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XYZ_MILL

from controller.blocks import HelixBlock, PathControl, Source
from controller.config import MachineConfig
from controller.errors import PlanningError
from controller.generator import helix_move
from controller.generator.helix_move import plan_helix
from controller.generator.plan import generate_reference
from controller.geometry.helix import HelixCurve


def helix(plane: str, r: float, a0: float, sweep: float, rise: float,
          feed_mm_s: float) -> HelixBlock:
    """A HelixBlock centred on the origin of its plane, from angle a0 through sweep."""
    curve = HelixCurve(plane, (0.0, 0.0), r, a0, sweep, 0.0, rise)
    start, end = curve.points([0.0, 1.0])
    clockwise = sweep < 0
    turns = max(0, math.ceil(abs(sweep) / (2 * math.pi)) - 1)  # the last one ends the sweep
    return HelixBlock(plane, tuple(start), tuple(end), (0.0, 0.0), clockwise, turns, feed_mm_s,
                      PathControl(), Source("p", 7, 7))


def reference(block: HelixBlock, config: MachineConfig) -> np.ndarray:
    chunks = list(generate_reference([block], config))
    return np.vstack([c.pos_mm for c in chunks])


def true_error_mm(block: HelixBlock, tool: np.ndarray) -> np.ndarray:
    curve = HelixCurve.from_block(block)
    n = max(2000, int(abs(block.sweep_rad) / 0.002))  # chords within r * 5e-7
    return nearest_mm(tool, curve.points(np.linspace(0.0, 1.0, n)))


def check_plan(block: HelixBlock, config: MachineConfig) -> tuple[float, float]:
    """Every limit of the plan; returns (motion time, worst 3-D contour error) in s and mm."""
    ip = config.interpolator
    T = config.sample_period_s  # noqa: N806
    ref = reference(block, config)
    start = np.array(block.start)
    assert ref[-1] == pytest.approx(block.end, abs=1e-12)
    steps = np.diff(np.vstack([start, ref]), axis=0) / T
    speed = np.linalg.norm(steps, axis=1)
    assert speed.max() <= min(block.feed_mm_s, ip.max_feed_mm_s) * (1 + 1e-6)
    for i, axis in enumerate(config.axes):
        assert np.abs(steps[:, i]).max() <= axis.max_velocity_mm_s * (1 + 1e-6)
    accel = np.linalg.norm(np.diff(np.vstack([np.zeros((1, 3)), steps, np.zeros((1, 3))]),
                                   axis=0) / T, axis=1)
    assert accel.max() <= ip.max_accel_mm_s2 * 1.01  # second differences of sampled motion
    tool = modelled_tool(ref, start, config)
    err = true_error_mm(block, tool)
    # eps_max less the quantisation the plan keeps for the machine (sqrt(3) pulses)
    assert err.max() <= ip.contour_error_limit_mm - math.sqrt(3) * 0.001 + 1e-6
    return len(ref) * T, float(err.max())


@settings(max_examples=12, deadline=None)
@given(st.sampled_from(["G17", "G18", "G19"]), st.floats(0.3, 60), st.floats(-3.1, 3.1),
       st.one_of(st.floats(0.2, 13), st.floats(-13, -0.2)), st.floats(-20, 20),
       st.floats(2, 60))
def test_helix_plans_keep_every_limit(plane: str, r: float, a0: float, sweep: float,
                                      rise: float, feed_mm_s: float) -> None:
    check_plan(helix(plane, r, a0, sweep, rise, feed_mm_s), XYZ_MILL)


def test_a_tight_arc_is_slowed_by_the_acceleration_and_the_servo() -> None:
    block = helix("G18", 0.5, 0.0, 2 * math.pi, 1.0, 58.0)
    profile, cap, worst = plan_helix(block, XYZ_MILL)
    kappa = HelixCurve.from_block(block).curvature_per_mm
    assert cap <= math.sqrt(XYZ_MILL.interpolator.max_accel_mm_s2 / math.sqrt(2) / kappa)
    assert worst <= 0.03
    check_plan(block, XYZ_MILL)


def test_a_tighter_contour_limit_lowers_the_feed() -> None:
    """Without pre-compensation (the paper's method) each axis lags by its servo: the plan
    slows until the lag normal to the path is within the limit."""
    block = helix("G19", 5.0, 0.0, math.pi, -2.0, 58.0)
    plain = dataclasses.replace(XYZ_MILL, interpolator=dataclasses.replace(
        XYZ_MILL.interpolator, servo_precompensation=False))
    _, cap_30, worst_30 = plan_helix(block, plain)
    strict = dataclasses.replace(plain, interpolator=dataclasses.replace(
        plain.interpolator, contour_error_limit_mm=0.010))
    _, cap_strict, worst_strict = plan_helix(block, strict)
    assert cap_strict < cap_30 and worst_strict <= 0.010 - math.sqrt(3) * 0.001 < worst_30
    check_plan(block, strict)


def test_a_limit_no_feed_can_keep_is_a_planning_error() -> None:
    impossible = dataclasses.replace(XYZ_MILL, interpolator=dataclasses.replace(
        XYZ_MILL.interpolator, contour_error_limit_mm=0.001))  # under the quantisation
    with pytest.raises(PlanningError, match="line 7: no feed keeps the contour error"):
        plan_helix(helix("G17", 5.0, 0.0, math.pi, 1.0, 20.0), impossible)


def test_a_long_helix_is_checked_on_a_copy_and_keeps_the_limit(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # A tenth of MAX_CHECK_SAMPLES (20 s), so the independent check runs on 25 s of motion, not
    # 250 s: 5 turns at 2 mm radius, 62.5 mm, over that bound at the capped feed.
    monkeypatch.setattr(helix_move, "MAX_CHECK_SAMPLES", helix_move.MAX_CHECK_SAMPLES // 10)
    block = helix("G17", 2.0, 0.0, 10 * math.pi, -1.0, 1.0)
    assert block.sweep_rad == pytest.approx(10 * math.pi)
    time_s, worst = check_plan(block, XYZ_MILL)
    assert time_s > 20.0 and worst <= 0.03
