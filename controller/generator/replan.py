"""One contour run through the four modules, re-planned until the predicted contour error fits."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from controller.config import MachineConfig
from controller.errors import PlanningError
from controller.generator.dynamics.braking import BrakingModel
from controller.generator.dynamics.checks import (
    LOOKBACK_S,
    TARGET_FRACTION,
    StopError,
    Violation,
    find_violations,
    near_stops,
    stop_errors,
)
from controller.generator.feed.path_plan import (
    FeedInput,
    FeedOutput,
    LimitPolicy,
    Reduction,
    plan_path_feed,
)
from controller.generator.feed.planner import PlanResult
from controller.generator.feed.shape import TransitionShape
from controller.generator.ph.construct import (
    BlockCurve,
    CornerInfo,
    Geometry,
    build_path,
    find_corners,
    widen,
)
from controller.generator.repeats import Repeats
from controller.generator.sampling import Interpolation, Samples, interpolate
from controller.geometry.path import Piece, PieceKind
from controller.servo.band import band_acceleration_gain_s2, band_servos, predict_band
from controller.servo.prediction import (
    ServoPrediction,
    ServoState,
    planning_limit_mm,
)
from controller.servo.true_distance import true_error_mm, worst_true_error_mm

# The first plan keeps kappa v^2 under this share of the planning limit / c2 (the steady contour
# error); the rest of the limit is left for the transients the dynamics module then measures.
# Since the true distance (not only eq. 28) and the quantisation margin count, measured over the
# three benchmarks and the 13 generated programs: 0.85 took 29 dynamics rounds in all, 0.80 took
# 18 for 0.2 % more motion time (and a real-time factor over 100 on all three benchmarks).
INITIAL_BUDGET_SHARE = 0.80


class RunStatus(StrEnum):
    OK = "ok"
    CONTOUR_LIMIT_NOT_MET = "contour error limit not met within the allowed dynamics rounds"
    FEED_PLAN_FAILED = "feed planning failed"


@dataclass(frozen=True)
class RunSettings:
    """Which variant of the four modules to run (ph-lookahead or Tsai's nurbs-lookahead)."""

    use_ph: bool = True
    policy: LimitPolicy = LimitPolicy.CONTINUOUS
    interpolation: Interpolation = Interpolation.PH_AND_EXACT_ARC_LENGTH
    widen_zones: bool = True


PH_LOOKAHEAD = RunSettings()
NURBS_LOOKAHEAD = RunSettings(False, LimitPolicy.CORNER_PLATEAU, Interpolation.SEQUENTIAL_TAYLOR)


@dataclass(frozen=True, eq=False, repr=False)
class RunPlan:
    """Reference points of one run and the report of how they were obtained."""

    samples: Samples
    start_xy_mm: np.ndarray
    geometry: Geometry
    prediction: ServoPrediction
    dynamics_rounds: int
    status: RunStatus
    plan_result: PlanResult
    planning_cpu_s: float

    @property
    def corners(self) -> tuple[CornerInfo, ...]:
        return self.geometry.corners


_MODELS: dict[tuple, BrakingModel] = {}  # per machine: the model memoises speeds


def _braking_model(config: MachineConfig) -> BrakingModel:
    ip = config.interpolator
    key = (config.sample_period_s, ip.max_accel_mm_s2, planning_limit_mm(config),
           tuple(a.servo for a in config.axes), tuple(a.servo_band for a in config.axes),
           ip.servo_precompensation)
    if key not in _MODELS:
        _MODELS[key] = BrakingModel(config, TARGET_FRACTION * planning_limit_mm(config))
    return _MODELS[key]


def _stops_mm(geo: Geometry) -> list[float]:
    """The run's stops in order: its inner stops (corners brought to rest), then its end."""
    return [*geo.path.stops_at_mm, geo.path.length_mm]


def _feed_input(config: MachineConfig, settings: RunSettings, reductions: tuple[Reduction, ...],
                stop_accels: dict[int, float], geo: Geometry,
                model: BrakingModel | None) -> FeedInput:
    ip = config.interpolator
    c2_s2 = band_acceleration_gain_s2(config)
    # Pre-compensated, c2 is about zero: the contour limit sets no normal-acceleration budget
    # (but for the plants of a servo band, which the compensation misses).
    budget = (INITIAL_BUDGET_SHARE * planning_limit_mm(config) / c2_s2 if c2_s2 > 1e-12
              else math.inf)
    # Stops are known by their order: a widened corner zone moves them along the path.
    stops = _stops_mm(geo)
    return FeedInput(ip.max_feed_mm_s, ip.max_accel_mm_s2, config.sample_period_s,
                     ip.chord_tolerance_mm, ip.reference_curvature_per_mm, budget,
                     settings.policy, reductions,
                     tuple((stops[i], a) for i, a in sorted(stop_accels.items())
                           if i < len(stops)), None if model is None else model.accel_for,
                     TransitionShape(ip.ramp_share))


# The true distance is computed exactly only where the tool is this share of eps_max or more
# from the path next to its own sample (that distance bounds it); elsewhere the bound stands in.
EXACT_ABOVE_SHARE = 0.9

# A stop's overshoot grows about as the square of its braking acceleration (51 um at Amax and
# 20 um at 0.61 Amax from 58 mm/s on Table II), so each round scales that acceleration by the
# square root of the ratio it must shrink by; never by more than these bounds in one round.
STOP_ACCEL_STEP = (0.5, 0.97)


def _soften_stops(stop_accels: dict[int, float], errors: tuple[StopError, ...],
                  limit_mm: float, used: tuple[float, ...]) -> None:
    """Lower the braking acceleration of each stop (by its order) the tool overshoots, from
    the one this round used."""
    for i, e in enumerate(errors):
        if e.error_mm > limit_mm and i < len(used):
            factor = np.clip(np.sqrt(TARGET_FRACTION * limit_mm / e.error_mm), *STOP_ACCEL_STEP)
            stop_accels[i] = float(used[i] * factor)


def _reduction(v: Violation, samples: Samples, limit_mm: float, lookback: int) -> Reduction:
    """Lower the feed over the stretch that led to a violation (up to LOOKBACK_S before it)."""
    last = samples.s_mm.size - 1
    lo = samples.s_mm[min(max(v.k_lo - lookback, 0), last)]
    hi = samples.s_mm[min(v.k_hi, last)]
    return Reduction(float(lo), float(hi), TARGET_FRACTION * limit_mm / v.peak_mm)


def _widen_at(geo: Geometry, curves: list[BlockCurve], zones: dict, s_mm: float) -> None:
    """Paper, Figure 4: widen the corner zone next to a violation on a NURBS part."""
    path = geo.path
    piece = path.pieces[int(path.piece_index(np.array([s_mm]))[0])]
    if piece.kind != PieceKind.NURBS or piece.corner >= 0:
        return
    # The block by its curve and line: a long program's windows share a curve between copies.
    block = next((i for i, bc in enumerate(curves)
                  if bc.curve is piece.curve and bc.line == piece.line), None)
    if block is None:
        return
    u = float(piece.u_at(np.array([s_mm]))[0])
    kappa = float(piece.curve.curvature(np.array([u]))[0])
    widen(curves, zones, block, u, 0.9 * kappa)


@dataclass(frozen=True, eq=False, repr=False)
class _Attempt:
    feed: FeedOutput
    samples: Samples | None = None
    prediction: ServoPrediction | None = None
    violations: tuple[Violation, ...] = ()
    stop_errors: tuple[StopError, ...] = ()


@dataclass(frozen=True, eq=False, repr=False)
class Continuation:
    """Where the previous look-ahead window was cut: the next window starts here, mid-cruise."""

    pieces: tuple[Piece, ...]  # geometry decided by the previous window, from the cut on
    tolerance_mm: float | None  # blend tolerance at the end of the last of those blocks
    v_mm_s: float  # the cruise feed at the cut (acceleration zero)
    xy_mm: np.ndarray  # reference point at the cut
    servo: ServoState  # servo model state at the cut
    end_mm: tuple[float, float, float]  # programmed end point of the last of those blocks
    history_xy: np.ndarray | None = None  # reference points up to the cut (its last one)
    band: tuple[ServoState, ...] = ()  # with a servo band, every plant's state (band_servos)


def _attempt(geo: Geometry, inp: FeedInput, start_xy_mm: np.ndarray, config: MachineConfig,
             settings: RunSettings, cache: dict, cont: Continuation | None) -> _Attempt:
    """Modules 3 and 4 once: plan the feed, interpolate, predict the contour error."""
    T = config.sample_period_s  # noqa: N806
    v0 = 0.0 if cont is None else cont.v_mm_s
    feed = plan_path_feed(geo.path, inp, cache, v_start_mm_s=v0)
    if feed.result != PlanResult.OK:
        return _Attempt(feed)
    samples = interpolate(geo.path, feed.profile, T, settings.interpolation)
    servos = band_servos(config)
    states = None if cont is None else (cont.band or (cont.servo,))
    preds = predict_band(samples.xy_mm, samples.phi_rad, start_xy_mm, servos, T, states)
    pred = preds[0]
    limit = planning_limit_mm(config)
    history = None if cont is None else cont.history_xy
    if len(preds) == 1:
        true_mm = true_error_mm(samples.xy_mm, pred, exact_above_mm=EXACT_ABOVE_SHARE * limit,
                                history_xy=history)
        contour_mm = np.abs(pred.contour_mm)
    else:  # a servo band: the worst plant at each sample
        true_mm = worst_true_error_mm(samples.xy_mm, preds, EXACT_ABOVE_SHARE * limit,
                                      history_xy=history)
        contour_mm = np.max([np.abs(p.contour_mm) for p in preds], axis=0)
    n = len(samples.xy_mm)
    stops = stop_errors(true_mm, samples.s_mm, _stops_mm(geo), n, T)
    # In motion the true distance stands beside eq. 28 (at a sharp curve it can exceed it);
    # around stops it is handled by the stops' braking (a curvature budget cannot help there).
    moving = np.where(near_stops(len(true_mm), stops, T, len(true_mm) - n), 0.0, true_mm)
    measure = np.maximum(contour_mm, moving)
    return _Attempt(feed, samples, pred, tuple(find_violations(measure, limit)), tuple(stops))


def _zones_signature(zones: dict) -> tuple:
    return tuple((i, tuple((z.u_start, z.u_end) for z in zs)) for i, zs in sorted(zones.items()))


def plan_contour_run(curves: list[BlockCurve], start_xy_mm: np.ndarray, config: MachineConfig,
                     settings: RunSettings = PH_LOOKAHEAD, cont: Continuation | None = None,
                     repeats: Repeats | None = None) -> RunPlan:
    """Modules 1-4 on one run of XY blocks to rest (Figure 4's loop), from rest or from where
    the previous look-ahead window was cut; repeats: what a long program's windows share.

    If a later round cannot be planned, the last plan is returned with its status."""
    cpu0 = time.process_time()
    ip = config.interpolator
    if repeats is None:
        zones = find_corners(curves, ip.kappa_threshold_per_mm)
    else:
        zones = {i: repeats.corners(bc.curve, ip.kappa_threshold_per_mm)
                 for i, bc in enumerate(curves) if bc.nurbs}
    reductions: tuple[Reduction, ...] = ()
    stop_accels: dict[int, float] = {}
    model = _braking_model(config) if settings.use_ph else None
    lookback = int(round(LOOKBACK_S / config.sample_period_s))
    status = RunStatus.CONTOUR_LIMIT_NOT_MET
    fit_cache: dict = {} if repeats is None else repeats.fits
    blend_cache: dict = {}
    sample_cache: dict = {}
    prefix = () if cont is None else cont.pieces
    tol = None if cont is None else cont.tolerance_mm
    good: tuple[Geometry, _Attempt] | None = None
    built: tuple[tuple, Geometry] | None = None
    for rounds in range(1, ip.max_dynamics_rounds + 1):
        # Only a widened corner zone changes the geometry: otherwise the round reuses it (and
        # with it every cache keyed by its pieces; build_path would give the same numbers).
        signature = _zones_signature(zones)
        if built is None or built[0] != signature:
            built = (signature, build_path(curves, zones, ip.ph_error_limit_mm, settings.use_ph,
                                           fit_cache, prefix, tol, blend_cache, repeats))
        geo = built[1]
        inp = _feed_input(config, settings, reductions, stop_accels, geo, model)
        att = _attempt(geo, inp, start_xy_mm, config, settings, sample_cache, cont)
        if att.samples is None:
            status = RunStatus.FEED_PLAN_FAILED
            break
        good = (geo, att)
        limit_mm = planning_limit_mm(config)
        overshoots = [e for e in att.stop_errors if e.error_mm > limit_mm]
        if not att.violations and not overshoots:
            status = RunStatus.OK
            break
        if rounds == ip.max_dynamics_rounds:
            break
        _soften_stops(stop_accels, att.stop_errors, limit_mm,
                      att.feed.stop_accels)
        samples = att.samples
        reductions += tuple(_reduction(v, samples, limit_mm, lookback)
                            for v in att.violations)
        if settings.widen_zones:
            last = len(samples.s_mm) - 1
            for v in att.violations:
                _widen_at(geo, curves, zones, float(samples.s_mm[min(v.k_peak, last)]))
    if good is None:
        raise PlanningError(f"feed planning failed: {att.feed.result.value}")
    geo, att = good
    assert att.samples is not None and att.prediction is not None
    return RunPlan(att.samples, start_xy_mm, geo, att.prediction, rounds, status,
                   att.feed.result, time.process_time() - cpu0)
