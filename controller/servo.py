"""Servo-loop model of one axis (paper eq. 27, Table II), discretised at the sample period.

Convention (ALGORITHMS.md section 3): the tracking error E = R - P is the output of the
4th-order E/V transfer function, zero-order-hold discretised, driven by the per-sample axis
velocity v[k] = (r[k] - r[k-1]) / T. With a0 = b0 the s factor of eq. 27 cancels, so
E/V = (s^3 + a3 s^2 + (a2 - b2) s + (a1 - b1)) / (s^4 + a3 s^3 + a2 s^2 + a1 s + a0)
(divided through by a4). This convention gives the steady ramp error V (a1 - b1) / a0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import cont2discrete, lfilter, lfilter_zi  # noqa: F401  (lfilter_zi for users)

from controller.config import ServoParams


@dataclass(frozen=True, slots=True)
class DiscreteServo:
    """Discrete E/V filter coefficients (b, a) for one axis at period T."""

    b: np.ndarray
    a: np.ndarray
    sample_period_s: float

    @property
    def steady_lag_s(self) -> float:
        """Error per unit velocity at steady state: E = lag * V."""
        return float(np.sum(self.b) / np.sum(self.a))


def error_transfer(p: ServoParams) -> tuple[np.ndarray, np.ndarray]:
    """Continuous E/V numerator and denominator (4th-order form, leading coefficient 1)."""
    num = np.array([p.a4, p.a3, p.a2 - p.b2, p.a1 - p.b1]) / p.a4
    if abs(p.a0 - p.b0) > 1e-9 * p.a0:
        # General case keeps the pole at s = 0 (eq. 27 as printed): E/V = (D - N) / (s D).
        num5 = np.array([p.a4, p.a3, p.a2 - p.b2, p.a1 - p.b1, p.a0 - p.b0]) / p.a4
        den5 = np.array([p.a4, p.a3, p.a2, p.a1, p.a0, 0.0]) / p.a4
        return num5, den5
    den = np.array([p.a4, p.a3, p.a2, p.a1, p.a0]) / p.a4
    return num, den


def discretise(p: ServoParams, sample_period_s: float) -> DiscreteServo:
    """Zero-order-hold discretisation of E/V at T."""
    num, den = error_transfer(p)
    b, a, _ = cont2discrete((num, den), sample_period_s, method="zoh")
    b = np.atleast_1d(np.squeeze(b))
    return DiscreteServo(b=b / a[0], a=np.asarray(a) / a[0], sample_period_s=sample_period_s)


def tracking_error_mm(servo: DiscreteServo, v_mm_s: np.ndarray) -> np.ndarray:
    """Tracking error of an axis at rest at t = 0, for per-sample velocities (vectorised)."""
    return lfilter(servo.b, servo.a, np.asarray(v_mm_s, dtype=float))


class AxisServoStepper:
    """Streaming form: feeds chunks of velocities and keeps the filter state between them."""

    def __init__(self, servo: DiscreteServo) -> None:
        self.servo = servo
        self.state = np.zeros(max(len(servo.a), len(servo.b)) - 1)

    def step(self, v_mm_s: np.ndarray) -> np.ndarray:
        """Tracking errors (mm) for the next chunk of per-sample velocities."""
        e, self.state = lfilter(self.servo.b, self.servo.a, np.asarray(v_mm_s, float),
                                zi=self.state)
        return e


def contour_error_mm(ex_mm: np.ndarray, ey_mm: np.ndarray, phi_rad: np.ndarray) -> np.ndarray:
    """Eq. 28: eps = -Ex sin(phi) + Ey cos(phi), phi the path tangent angle."""
    return -ex_mm * np.sin(phi_rad) + ey_mm * np.cos(phi_rad)
