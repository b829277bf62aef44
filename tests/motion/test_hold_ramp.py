"""The feed hold's ramp: its stop shape at Amax by arc length along the rows, never faster than
the plan, checked on the servo model; on the shipped config (pre-compensated, ramp_share 0.1)
in virtual time."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from refgen import circle_chunks

from controller.config import load_config
from controller.generator.plan import generate_reference
from controller.interpreter.program import read_program
from controller.motion.hold_ramp import (
    ACCEL_SHARE,
    HOLD_FALL_SHARE,
    hold_distances_mm,
    hold_shape,
    hold_steps,
)
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.ramp_first import HOLD_KEEP_MS, PLAN_BUDGET_MS
from controller.motion.source import ChunkSource
from controller.motion.types import MotionProgress, MotionSettings, MotionState, Outcome
from controller.transition_shape import StopShape, TransitionShape
from drivers.sim.card import SimCard

CFG = load_config("xy_table")
T = CFG.sample_period_s
AMAX = CFG.interpolator.max_accel_mm_s2
SHAPE = TransitionShape(CFG.interpolator.ramp_share)
HOLD = hold_shape(CFG.interpolator.ramp_share)
TAU = np.linspace(0.0, 1.0, 100001)
V_MM_S = 58.333  # the circle's feed (refgen.circle_chunks)
BUTTERFLY = Path(__file__).resolve().parents[2] / "nc_programs" / "butterfly.nc"


def _ramp_samples(v_mm_s: float, shape: TransitionShape | StopShape = HOLD) -> int:
    return math.ceil(shape.time_factor * v_mm_s / (ACCEL_SHARE * AMAX) / T - 1e-9)


def test_the_hold_shape_rises_as_the_planner_and_falls_long() -> None:
    assert isinstance(HOLD, StopShape) and HOLD.rise_share == 0.5 * CFG.interpolator.ramp_share
    assert HOLD.fall_share == HOLD_FALL_SHARE
    assert hold_shape(1.0) == TransitionShape(1.0)  # the quintic stays the quintic


def test_a_stop_shape_with_equal_shares_is_the_transition_shape() -> None:
    for share in (0.1, 0.5, 1.0):
        stop, same = StopShape(share / 2, share / 2), TransitionShape(share)
        for f in ("speed", "distance", "accel"):
            assert np.abs(getattr(stop, f)(TAU) - getattr(same, f)(TAU)).max() < 1e-14
        assert abs(stop.total_share - 0.5) < 1e-15


def test_a_stop_shape_is_a_smooth_transition() -> None:
    for rise, fall in ((0.05, 0.8), (0.02, 0.3), (0.3, 0.7)):
        shape = StopShape(rise, fall)
        g, big_g, a = shape.speed(TAU), shape.distance(TAU), shape.accel(TAU)
        h = TAU[1]
        assert g[0] == 0.0 and abs(g[-1] - 1.0) < 1e-12 and np.all(np.diff(g) >= -1e-15)
        assert abs(big_g[-1] - shape.total_share) < 1e-12 and big_g[0] == 0.0
        # G' = g, g' = a, a peaks at the factor, and G(1) is the integral of g.
        assert np.abs(np.gradient(big_g, h) - g).max() < 1e-6
        assert np.abs(np.gradient(g, h)[1:-1] - a[1:-1]).max() < 1e-3
        assert abs(a.max() - shape.peak_factor) < 1e-9 and a[0] == 0.0 and a[-1] == 0.0
        assert abs(np.trapezoid(g, TAU) - shape.total_share) < 1e-9


def test_the_distances_are_the_shape_at_amax_to_rest() -> None:
    for shape in (HOLD, SHAPE, TransitionShape(1.0)):
        d = hold_distances_mm(V_MM_S, AMAX, T, shape)
        assert len(d) == _ramp_samples(V_MM_S, shape)
        total = 1.0 - (shape.total_share if isinstance(shape, StopShape) else 0.5)
        assert abs(d[-1] - V_MM_S * len(d) * T * total) < 1e-12  # v0 T (1 - G(1))
        speed = np.diff(d, prepend=0.0) / T
        decel = -np.diff(np.r_[V_MM_S, speed]) / T
        assert decel.max() <= ACCEL_SHARE * AMAX * 1.02 and decel.min() >= -1e-6
        assert speed[-1] < 0.02 * V_MM_S


def test_steps_follow_the_distances_on_rows_at_the_plans_speed() -> None:
    rows = np.column_stack([np.arange(400) * V_MM_S * T, np.zeros(400)])  # a line at v
    d = hold_distances_mm(V_MM_S, AMAX, T, SHAPE)
    steps = hold_steps(rows, 10.25, d)
    assert np.allclose(np.cumsum(steps) * V_MM_S * T, d)
    assert steps.max() <= 1.0 + 1e-12  # the shape is never faster than the rows


def test_steps_never_outrun_a_plan_that_slows_down_faster() -> None:
    speed = np.maximum(V_MM_S - 3000.0 * np.arange(60) * T, 20.0)  # braking harder than Amax
    rows = np.column_stack([np.cumsum(speed) * T, np.zeros(60)])
    steps = hold_steps(rows, 0.0, hold_distances_mm(V_MM_S, AMAX, T, SHAPE))
    assert steps.max() <= 1.0 + 1e-12
    assert steps[:3].min() > 0.99  # it follows the plan's braking while that is the slower


def test_rows_that_come_to_rest_first_are_followed_there() -> None:
    speed = np.r_[np.full(5, V_MM_S), np.zeros(30)]
    rows = np.column_stack([np.cumsum(speed) * T, np.zeros(35)])
    steps = hold_steps(rows, 0.0, hold_distances_mm(V_MM_S, AMAX, T, SHAPE))
    assert np.sum(steps) == 4.0 and steps.max() == 1.0  # to row 4, the plan's own stop


def _hold_on(chunks: list, at_s: float) -> tuple[object, np.ndarray, dict]:
    """The chunks on the virtual sim card, a hold at executed time at_s, resumed once held:
    (result, the XY rows the card ran, {asked: frames executed then})."""
    card = SimCard(CFG, realtime=False)
    card.open()
    settings = MotionSettings.from_config(CFG, progress_every_s=T)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    info: dict = {}
    sent: list[tuple[int, np.ndarray]] = []

    def progress(p: MotionProgress) -> None:
        if "asked" not in info and p.executed_s >= at_s:
            info["asked"] = round(p.executed_s / T)
            ctrl.request_hold()
        if p.state is MotionState.HELD and "held" not in info:
            info["held"] = True
            ctrl.request_resume()

    ctrl = MotionController(CFG, card, ChunkSource(chunks), pacer, settings, on_progress=progress)
    send = ctrl._send

    def record(rows: np.ndarray, end: bool, pause: bool = False) -> None:
        sent.append((ctrl.stream.sent, rows[:, :2].copy()))
        send(rows, end, pause)

    ctrl._send = record  # type: ignore[method-assign]
    result = ctrl.run()
    card.close()
    xy = np.full((ctrl.stream.sent, 2), np.nan)
    for start, rows in sent:  # later sends replace the frames taken back
        xy[start : start + len(rows)] = rows[: max(0, ctrl.stream.sent - start)]
    return result, xy, info


def _frames_to_rest(xy: np.ndarray, k0: int) -> int:
    """Frames from the request until the wanted path stands still."""
    step = np.linalg.norm(np.diff(xy[k0:], axis=0), axis=1)
    return 1 + int(np.flatnonzero(step == 0.0)[0])


def _bound(v_mm_s: float) -> int:
    """The request is seen at the next cycle (2 frames), the card runs what it kept and what
    it runs while the ramp is planned (virtual time: nothing runs then), then the ramp: the
    shape at Amax from v, and the sample at rest that ends it."""
    kept = math.ceil(HOLD_KEEP_MS * 1e-3 / T) + math.ceil(PLAN_BUDGET_MS * 1e-3 / T)
    return 2 * 2 + kept + _ramp_samples(v_mm_s) + 2


def test_a_hold_on_the_circle_starts_at_once_and_rests_after_the_shape() -> None:
    result, xy, info = _hold_on(list(circle_chunks()), 0.4)
    assert result.outcome is Outcome.DONE and result.underruns == 0  # type: ignore[attr-defined]
    assert result.contour_error_um["max"] <= 30.0  # type: ignore[attr-defined]
    assert _frames_to_rest(xy, info["asked"]) <= _bound(V_MM_S)


def test_a_hold_while_the_plan_brakes_rests_as_soon() -> None:
    """Where the plan itself brakes near Amax no ramp in the time scale kept Amax, and the
    hold took seconds; by arc length, never faster than the plan, it is at rest as soon."""
    chunks = list(generate_reference(read_program(str(BUTTERFLY), CFG), CFG))
    feed = np.concatenate([c.feed_mm_s for c in chunks])
    braking = np.flatnonzero(np.diff(feed) / T < -0.5 * AMAX)
    k = int(braking[len(braking) // 3])
    result, xy, info = _hold_on(chunks, k * T)
    assert result.outcome is Outcome.DONE and result.underruns == 0  # type: ignore[attr-defined]
    assert result.contour_error_um["max"] <= 30.0  # type: ignore[attr-defined]
    assert _frames_to_rest(xy, info["asked"]) <= _bound(float(feed[:k].max()))
