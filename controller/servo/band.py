"""A servo band (`axes.<a>.servo_band`): the plants a plan is checked on when the loop may be off
its model, and their predictions; the generator keeps the worst of them within eps_max.

Which plants. A plant of the band is the model with its poles moved by a factor k (1 +- pole_pct)
and its velocity and acceleration lags scaled by g (1 +- gain_pct), per axis (model.mismatched).
For the slow feed changes the planner makes (quintic feeds, a few Hz against a 70 Hz loop) each
axis's error is about dc1 v + dc2 a, with dc1 = c1 (g / k - 1) and dc2 = c2 (g / k^2 - 1)
pre-compensated (the compensation inverts the model: c1, c2 are the model's), c1 g / k and
c2 g / k^2 without. Both are monotonic in k and in g, and the contour error is the size of a
linear function of them: its largest value over a box of (g, 1/k) is at a corner, but for the
bulge of g / k^2 along the pole edges (a parabola in 1/k), at most g c2 a (1/k_lo - 1/k_hi)^2 / 4:
4.7 % of c2 a at +-20 % poles and +10 % lags, 3.3 um at Amax on Table II, inside the margin the
re-planning keeps (it aims at 0.95 of the planning limit, itself eps_max less sqrt(2) pulses).
Hence the corners: the axes are separate loops, so one may be slow while the other is fast (a
diagonal line then shows the difference of their lags as a contour error), and every combination
of the axes' corners is checked, with the model itself: 17 plants for a band on X and on Y.
bench/band.py checks the claim on denser plants (pole edges' midpoints) and the real programs.
"""

from __future__ import annotations

import itertools

import numpy as np

from controller.config import AxisConfig, MachineConfig, ServoParams
from controller.servo.model import (
    DiscreteServo,
    discretise,
    filter_block,
    filter_state,
    mismatched,
    small_s_gains,
)
from controller.servo.precompensation import mismatched_residual_servo
from controller.servo.prediction import (
    ServoPrediction,
    ServoState,
    acceleration_gain_s2,
    axis_servos,
    predict,
)

ServoPair = tuple[DiscreteServo, DiscreteServo]  # the X and Y filters of one plant


def axis_plants(axis: AxisConfig) -> tuple[ServoParams, ...]:
    """The axis's model, then its band's corners (a side of zero width gives one corner)."""
    band = axis.servo_band
    if band is None:
        return (axis.servo,)
    poles = sorted({-band.pole_pct, band.pole_pct})
    gains = sorted({-band.gain_pct, band.gain_pct})
    corners = [mismatched(axis.servo, pole, gain) for pole in poles for gain in gains
               if (pole, gain) != (0.0, 0.0)]
    return (axis.servo, *corners)


def has_band(config: MachineConfig) -> bool:
    return any(config.axis(a).servo_band is not None for a in ("x", "y"))


def band_plants(config: MachineConfig) -> tuple[tuple[ServoParams, ServoParams], ...]:
    """(X, Y) loops of every plant checked: the model first, then each combination of the two
    axes' corners (an axis without a band is its model in every one)."""
    xs, ys = axis_plants(config.axis("x")), axis_plants(config.axis("y"))
    first = (xs[0], ys[0])
    if len(xs) == 1 and len(ys) == 1:
        return (first,)
    return (first, *itertools.product(xs[1:] or xs, ys[1:] or ys))


def band_servos(config: MachineConfig) -> tuple[ServoPair, ...]:
    """Per plant of band_plants: wanted path -> that plant's tool's distance from it, per axis.
    Pre-compensated, the motion loop inverts the model (not the plant): the residual of the
    model's compensation on that plant; otherwise the plant's own E/V. Without a band, the one
    pair axis_servos gives."""
    nominal = axis_servos(config)
    if not has_band(config):
        return (nominal,)
    T = config.sample_period_s  # noqa: N806
    mx, my = config.axis("x").servo, config.axis("y").servo

    def one(plant: ServoParams, model: ServoParams) -> DiscreteServo:
        if config.interpolator.servo_precompensation:
            return mismatched_residual_servo(plant, model, T)
        return discretise(plant, T)
    return (nominal, *((one(px, mx), one(py, my)) for px, py in band_plants(config)[1:]))


def band_acceleration_gain_s2(config: MachineConfig) -> float:
    """acceleration_gain_s2, the worst over the band's plants (the model's without a band)."""
    if not has_band(config):
        return acceleration_gain_s2(config)
    if config.interpolator.servo_precompensation:
        return max(abs(small_s_gains(s)[1]) for pair in band_servos(config) for s in pair)
    return max((p.a2 - p.b2) / p.a0 - p.a1 * (p.a1 - p.b1) / p.a0**2
               for pair in band_plants(config) for p in pair)


def predict_band(xy_mm: np.ndarray, phi_rad: np.ndarray, start_xy_mm: np.ndarray,
                 servos: tuple[ServoPair, ...], sample_period_s: float,
                 states: tuple[ServoState, ...] | None = None) -> tuple[ServoPrediction, ...]:
    """prediction.predict for every plant; an axis filter shared by several plants (17 plants
    have 5 filters per axis) is run once, its state being the same in each."""
    if len(servos) == 1:
        return (predict(xy_mm, phi_rad, start_xy_mm, servos[0], sample_period_s,
                        None if not states else states[0]),)
    nominal = predict(xy_mm, phi_rad, start_xy_mm, servos[0], sample_period_s,
                      None if not states else states[0])
    settle = len(nominal.ex_mm) - len(xy_mm)
    xy = np.vstack([xy_mm, np.repeat(xy_mm[-1:], settle, axis=0)])
    v = np.diff(np.vstack([start_xy_mm[None, :], xy]), axis=0) / sample_period_s
    phi = np.r_[phi_rad, np.full(settle, phi_rad[-1])]
    sin, cos = np.sin(phi), np.cos(phi)
    memo: dict[tuple[int, int], np.ndarray] = {}
    out = [nominal]
    for i, pair in enumerate(servos[1:], start=1):
        e = []
        for axis, servo in enumerate(pair):
            key = (axis, id(servo))
            if key not in memo:
                state = np.zeros(servo.order) if not states else states[i][axis]
                memo[key] = filter_block(servo, v[:, axis], state)[0]
            e.append(memo[key])
        out.append(ServoPrediction(e[0], e[1], -e[0] * sin + e[1] * cos))
    return tuple(out)


def band_states_after(xy_mm: np.ndarray, start_xy_mm: np.ndarray, servos: tuple[ServoPair, ...],
                      sample_period_s: float,
                      states: tuple[ServoState, ...] | None = None) -> tuple[ServoState, ...]:
    """Every plant's filter states after following xy_mm (prediction.state_after for each)."""
    v = np.diff(np.vstack([start_xy_mm[None, :], xy_mm]), axis=0) / sample_period_s
    out = []
    for i, pair in enumerate(servos):
        out.append(tuple(filter_state(s, v[:, axis], np.zeros(s.order) if not states
                                      else states[i][axis]) for axis, s in enumerate(pair)))
    return tuple(out)  # type: ignore[arg-type]
