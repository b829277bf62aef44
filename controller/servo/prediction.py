"""Servo-model prediction of tracking and contour errors (eqs. 27-28) along a reference."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from controller.servo.model import (
    DiscreteServo,
    contour_error_mm,
    discretise,
    filter_block,
    filter_state,
    small_s_gains,
)
from controller.servo.precompensation import residual_servo

SETTLE_S = 0.06  # simulate this long at rest after the run so the tail error is seen too


@dataclass(frozen=True, eq=False, repr=False)
class ServoPrediction:
    """Per-sample tracking errors (mm) of X and Y and the contour error (eq. 28)."""

    ex_mm: np.ndarray
    ey_mm: np.ndarray
    contour_mm: np.ndarray


def planning_limit_mm(config: MachineConfig) -> float:
    """eps_max less what quantisation adds on the machine, so that the measured error keeps
    eps_max too: the commanded steps are the reference rounded to pulses, and the encoder reads
    the tool to a pulse; up to half a pulse each per axis, sqrt(2) pulses in the plane."""
    pulse_mm = max(a.pulse_mm for a in config.axes)
    return config.interpolator.contour_error_limit_mm - math.sqrt(2.0) * pulse_mm


def plant_servos(config: MachineConfig) -> tuple[DiscreteServo, DiscreteServo]:
    """E/V of the X and Y loops themselves: reference sent -> tracking error."""
    T = config.sample_period_s  # noqa: N806
    return discretise(config.axis("x").servo, T), discretise(config.axis("y").servo, T)


def axis_servos(config: MachineConfig) -> tuple[DiscreteServo, DiscreteServo]:
    """What the generator predicts with: wanted path -> its distance from the model's actual
    position, per axis. The plain loops, or with servo_precompensation the residual of the
    compensated loops (the reference sent then leads the wanted path)."""
    if not config.interpolator.servo_precompensation:
        return plant_servos(config)
    T = config.sample_period_s  # noqa: N806
    return residual_servo(config.axis("x").servo, T), residual_servo(config.axis("y").servo, T)


def acceleration_gain_s2(config: MachineConfig) -> float:
    """c2 of the small-s expansion e ~ c1 v + c2 a (docs/algorithms.md,
    The servo model (eq. 27)): the worse of X and Y.

    The contour error on a curve is about c2 * kappa * v^2, so eps_max / c2 is the normal
    acceleration the servo loop can follow within the contour limit. Pre-compensated, c2 is
    that of the residual (zero by construction, see precompensation.compensation_filter)."""
    if config.interpolator.servo_precompensation:
        return max(abs(small_s_gains(s)[1]) for s in axis_servos(config))
    gains = []
    for name in ("x", "y"):
        p = config.axis(name).servo
        gains.append((p.a2 - p.b2) / p.a0 - p.a1 * (p.a1 - p.b1) / p.a0**2)
    return max(gains)


ServoState = tuple[np.ndarray, np.ndarray]  # filter states of X and Y


def rest_state(servos: tuple[DiscreteServo, DiscreteServo]) -> ServoState:
    return np.zeros(servos[0].order), np.zeros(servos[1].order)


def _velocities(xy_mm: np.ndarray, start_xy_mm: np.ndarray, sample_period_s: float) -> np.ndarray:
    return np.diff(np.vstack([start_xy_mm[None, :], xy_mm]), axis=0) / sample_period_s


def predict(xy_mm: np.ndarray, phi_rad: np.ndarray, start_xy_mm: np.ndarray,
            servos: tuple[DiscreteServo, DiscreteServo], sample_period_s: float,
            state: ServoState | None = None) -> ServoPrediction:
    """Drive each axis model with its per-sample velocity, from rest or from a servo state (a
    window continuing the previous one); the run ends at rest.

    Returns errors for the run's samples followed by SETTLE_S of samples holding the end point."""
    settle = int(round(SETTLE_S / sample_period_s))
    xy = np.vstack([xy_mm, np.repeat(xy_mm[-1:], settle, axis=0)])
    v = _velocities(xy, start_xy_mm, sample_period_s)
    sx, sy = rest_state(servos) if state is None else state
    ex = filter_block(servos[0], v[:, 0], sx)[0]
    ey = filter_block(servos[1], v[:, 1], sy)[0]
    phi = np.r_[phi_rad, np.full(settle, phi_rad[-1])]
    return ServoPrediction(ex, ey, contour_error_mm(ex, ey, phi))


def state_after(xy_mm: np.ndarray, start_xy_mm: np.ndarray,
                servos: tuple[DiscreteServo, DiscreteServo], sample_period_s: float,
                state: ServoState | None = None) -> ServoState:
    """The servo filter states after following xy_mm from start_xy_mm (and state)."""
    v = _velocities(xy_mm, start_xy_mm, sample_period_s)
    sx, sy = rest_state(servos) if state is None else state
    return filter_state(servos[0], v[:, 0], sx), filter_state(servos[1], v[:, 1], sy)
