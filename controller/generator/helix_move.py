"""A helix or a G18/G19 arc (HelixBlock) planned as 3-axis motion from rest to rest: its exact
arc length, a quintic feed profile under the feed, velocity and acceleration limits of every
axis, and the contour error, the modelled tool's true distance from the 3-D curve, checked
through each axis's servo model; the feed is lowered until it holds.

The four modules meet it as follows: it has no sharp corner (module 1) and needs no PH blend
(module 2: its arc length is exact already); the feed profile is module 3's plan_feed; the
dynamics check (module 4) is the servo model of every axis, as the motion loop drives it (X and
Z pre-compensated as X and Y when the config says so)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from controller.blocks import HelixBlock
from controller.config import MachineConfig
from controller.errors import PlanningError
from controller.generator.feed.planner import PlanResult, plan_feed
from controller.generator.feed.profile import FeedProfile
from controller.generator.long_blocks import chunk_bounds
from controller.geometry.helix import HelixCurve
from controller.refpoints import RefChunk
from controller.servo.model import DiscreteServo, discretise, filter_block
from controller.servo.precompensation import residual_servo
from controller.servo.prediction import SETTLE_S

# The path acceleration is split between the tangent and the normal so that the total stays
# within Amax: |a|^2 = a_t^2 + (v^2 kappa)^2 <= 2 (Amax / sqrt 2)^2.
SHARE = 1.0 / math.sqrt(2.0)
FEED_STEP = 0.85  # each re-planning round lowers the cruise feed by this factor
MAX_ROUNDS = 40  # 0.85^40 = 0.0015 of the first feed
# Samples whose contour error is computed: a longer helix is checked on a copy of this length
# with the same radius, pitch and cruise. Its error in the cruise is steady (constant curvature
# and speed: every axis sees a sine or a constant), so the copy's ramps and cruise bound it.
MAX_CHECK_SAMPLES = 200_000


def axis_error_servos(config: MachineConfig) -> list[DiscreteServo]:
    """Per machine axis: wanted position -> wanted minus the model's actual, as the motion
    loop drives it (with servo_precompensation it pre-compensates every axis)."""
    T = config.sample_period_s  # noqa: N806
    pre = config.interpolator.servo_precompensation
    return [residual_servo(a.servo, T) if pre else discretise(a.servo, T) for a in config.axes]


def feed_cap_mm_s(block: HelixBlock, curve: HelixCurve, config: MachineConfig) -> float:
    """The programmed feed within the machine's feed, each axis's velocity (the largest share
    of the tangent an axis can take) and the normal acceleration's share of Amax."""
    ip = config.interpolator
    cap = min(block.feed_mm_s, ip.max_feed_mm_s)
    d = curve.evaluate(np.linspace(0.0, 1.0, 65), 1)[1]
    share = np.abs(d).max(axis=0) / curve.length_mm  # per axis: |dx_i / ds| at most
    for axis, frac in zip(config.axes, share, strict=True):
        if frac > 1e-9:  # an axis the arc barely moves cannot limit it
            cap = min(cap, axis.max_velocity_mm_s / frac)
    kappa = curve.curvature_per_mm
    if kappa > 0:
        cap = min(cap, math.sqrt(SHARE * ip.max_accel_mm_s2 / kappa))
    return cap


def _profile(length_mm: float, cap_mm_s: float, accel_mm_s2: float, line: int) -> FeedProfile:
    plan = plan_feed(np.array([0.0, length_mm]), np.array([cap_mm_s, cap_mm_s]), accel_mm_s2)
    if plan.result is not PlanResult.OK:
        raise PlanningError(f"line {line}: arc feed profile: {plan.result.value}")
    return plan.profile


def sample(curve: HelixCurve, profile: FeedProfile, sample_period_s: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, positions (k, 3), feed) at every period of the profile, ending on the end point."""
    k = max(int(np.ceil(profile.duration_s / sample_period_s - 1e-9)), 1)
    t = np.minimum(np.arange(1, k + 1) * sample_period_s, profile.duration_s)
    s, v, _ = profile.evaluate(t)
    u = np.clip(s / curve.length_mm, 0.0, 1.0)
    u[-1] = 1.0
    return u, curve.points(u), v


def contour_error_mm(curve: HelixCurve, u: np.ndarray, pos: np.ndarray,
                     servos: list[DiscreteServo], sample_period_s: float) -> np.ndarray:
    """The modelled tool's distance from the curve at every sample and through SETTLE_S after
    the end (the end point held), the tool starting at rest on the curve's start."""
    settle = int(round(SETTLE_S / sample_period_s))
    ref = np.vstack([pos, np.repeat(pos[-1:], settle, axis=0)])
    v = np.diff(np.vstack([curve.points([0.0]), ref]), axis=0) / sample_period_s
    err = np.column_stack([filter_block(s, v[:, i], np.zeros(s.order))[0]
                           for i, s in enumerate(servos)])
    guess = np.r_[u, np.ones(settle)]
    return curve.distance_mm(ref - err, guess)


def _check_copy(curve: HelixCurve, cap_mm_s: float, accel_mm_s2: float,
                sample_period_s: float) -> HelixCurve:
    """The helix itself, or for a long one a shorter copy (same radius, pitch, start) long
    enough for both ramps and a cruise of a second at cap."""
    ramps_mm = 4.0 * cap_mm_s**2 / accel_mm_s2 + cap_mm_s * 1.0
    if curve.length_mm / max(cap_mm_s, 1e-9) / sample_period_s <= MAX_CHECK_SAMPLES or \
            ramps_mm >= curve.length_mm:
        return curve
    f = ramps_mm / curve.length_mm
    return HelixCurve(curve.plane, curve.center, curve.radius, curve.angle0, curve.sweep * f,
                      curve.n0, curve.rise * f, curve.radius_change * f)


def plan_helix(block: HelixBlock, config: MachineConfig) -> tuple[FeedProfile, float, float]:
    """(profile, cruise cap, worst predicted contour error in mm) of a plan within the limit,
    lowering the feed from feed_cap_mm_s until the servo model keeps the contour error within
    eps_max less the quantisation of three axes; PlanningError if none within MAX_ROUNDS."""
    curve = HelixCurve.from_block(block)
    T = config.sample_period_s  # noqa: N806
    accel = SHARE * config.interpolator.max_accel_mm_s2
    pulse_mm = max(a.pulse_mm for a in config.axes)
    limit_mm = config.interpolator.contour_error_limit_mm - math.sqrt(3.0) * pulse_mm
    servos = axis_error_servos(config)
    line = block.source.first_line
    cap = feed_cap_mm_s(block, curve, config)
    for _ in range(MAX_ROUNDS):
        check = _check_copy(curve, cap, accel, T)
        u, pos, _ = sample(check, _profile(check.length_mm, cap, accel, line), T)
        worst = float(contour_error_mm(check, u, pos, servos, T).max())
        if worst <= limit_mm:
            return _profile(curve.length_mm, cap, accel, line), cap, worst
        cap *= FEED_STEP
    raise PlanningError(f"line {line}: no feed keeps the contour error of this arc within "
                        f"{limit_mm * 1000:.1f} um")


def helix_move(block: HelixBlock, config: MachineConfig, t0_s: float
               ) -> Iterator[tuple[RefChunk, bool]]:
    """The planned reference points in chunks of at most CHUNK_SAMPLES, each with whether it
    is the last; the last row is the programmed end point."""
    curve = HelixCurve.from_block(block)
    if curve.length_mm < 1e-9:
        return
    profile, _, _ = plan_helix(block, config)
    T = config.sample_period_s  # noqa: N806
    k = max(int(np.ceil(profile.duration_s / T - 1e-9)), 1)
    end = np.array(block.end)
    for i0, i1 in chunk_bounds(k):
        t = np.minimum(np.arange(i0 + 1, i1 + 1) * T, profile.duration_s)
        s, v, _ = profile.evaluate(t)
        pos = curve.points(np.clip(s / curve.length_mm, 0.0, 1.0))
        if i1 == k:
            pos[-1] = end
        line = np.full(len(pos), block.source.first_line, np.int32)
        yield RefChunk(t0_s + (i0 + 1) * T, pos, v, line), i1 == k
