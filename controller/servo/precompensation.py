"""Servo pre-compensation: the reference sent to a drive leads the wanted path by the model's lag.

The Table II loop follows its reference R with P/R = N/D (docs/algorithms.md, Pre-compensation),
N = b2 s^2 + b1 s + b0 and D the 4th-order denominator: at speed it lags behind
(c1 v along the path) and cuts inside every curve (c2 kappa v^2). Sending R = (D/N) P makes the
model follow P itself. D/N is improper (the plant has relative degree 2), so it is split into
derivative terms and a stable strictly proper rest. With V the wanted axis velocity,

    R - P = ((D - N) / (s N)) V = (q1 s + q0) V + (Rm(s) / (s N)) V,

the rest discretised like the E/V model (zero-order hold on the per-sample velocity) and the
derivative by a backward difference, so the filter is causal: a frame depends on the wanted path up
to its own sample and can be computed in the motion loop as frames go out (after a hold or an
override has re-timed the path, which a compensation computed by the planner would not survive).
N's zeros are the plant's (-90 and -146 rad/s on Table II): stable, so the rest decays.

What the compensated loop leaves is again a linear filter of the wanted velocity,

    P - actual = -Y V + H (V + diff(Y V) / T),

Y the compensation and H the plant's E/V; `residual_servo` returns it as a DiscreteServo so the
dynamics module predicts the compensated machine exactly as it predicts the plain one.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from controller.config import ServoParams
from controller.servo.model import (
    DiscreteServo,
    discretise,
    small_s_gains,
    zoh,
)
from controller.servo.stacked import StackedFilter

# Frames appended at a standstill until the lead has died away to this (a fraction of a pulse).
SETTLED_LEAD_MM = 1e-5
MAX_SETTLE_FRAMES = 1000


def _polys(p: ServoParams) -> tuple[np.ndarray, np.ndarray]:
    den = np.array([p.a4, p.a3, p.a2, p.a1, p.a0]) / p.a4
    num = np.array([0.0, 0.0, p.b2, p.b1, p.b0]) / p.a4
    return den, num


def supported(p: ServoParams) -> bool:
    """Pre-compensation needs a loop without steady position error (a0 = b0, Table II)."""
    return abs(p.a0 - p.b0) <= 1e-9 * p.a0


def _padd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sum of two polynomials in z^-1 (coefficient 0 first)."""
    n = max(len(a), len(b))
    return np.r_[a, np.zeros(n - len(a))] + np.r_[b, np.zeros(n - len(b))]


@lru_cache(maxsize=64)
def compensation_filter(p: ServoParams, sample_period_s: float) -> DiscreteServo:
    """Y: per-sample wanted velocity (mm/s) -> lead R - P (mm), causal, with a direct term.

    The backward difference lags half a sample, which leaves the residual a small acceleration
    gain (-1.7e-6 s^2 on Table II, 6 % of the plain loop's c2); the derivative term's gain is
    trimmed by it once so the residual's c2 is zero (8.8 instead of 10.5 um on the butterfly)."""
    first = _compensation(p, sample_period_s, 0.0)
    trim = small_s_gains(_residual(p, first, sample_period_s))[1]
    return _compensation(p, sample_period_s, trim)


def _compensation(p: ServoParams, sample_period_s: float, q1_trim: float) -> DiscreteServo:
    if not supported(p):
        raise ValueError("servo pre-compensation needs a0 = b0 (a loop without position error)")
    den, num = _polys(p)
    lead_over_v = (den - num)[:-1]  # (D - N) / s: the constant terms cancel (a0 = b0)
    n2 = num[2:]
    quotient, rest = np.polydiv(lead_over_v, n2)  # (q1 s + q0), rest of degree <= 1
    q1, q0 = (quotient[-2], quotient[-1]) if len(quotient) > 1 else (0.0, quotient[-1])
    b_rest, a_rest = zoh(rest / n2[0], n2 / n2[0], sample_period_s)
    b_rest, a_rest = b_rest / a_rest[0], a_rest / a_rest[0]
    T = sample_period_s  # noqa: N806
    q1 += q1_trim
    # y = q1 (v[k] - v[k-1]) / T + q0 v[k] + rest: one fraction over a_rest.
    direct = np.convolve(np.array([q1 / T + q0, -q1 / T]), a_rest)
    return _fraction(_padd(direct, b_rest), a_rest, T)


def _fraction(num: np.ndarray, den: np.ndarray, sample_period_s: float) -> DiscreteServo:
    """num/den in z^-1 as a DiscreteServo: a numerator longer than the denominator is a pure
    delay, poles at z = 0 appended to the denominator."""
    if len(num) > len(den):
        den = np.r_[den, np.zeros(len(num) - len(den))]
    return DiscreteServo(b=num, a=den, sample_period_s=sample_period_s)


@lru_cache(maxsize=64)
def residual_servo(p: ServoParams, sample_period_s: float) -> DiscreteServo:
    """W: per-sample wanted velocity -> P - actual of the compensated loop (see the module)."""
    return _residual(p, compensation_filter(p, sample_period_s), sample_period_s)


@lru_cache(maxsize=256)
def mismatched_residual_servo(plant: ServoParams, model: ServoParams,
                              sample_period_s: float) -> DiscreteServo:
    """P - actual when the compensation inverts `model` but the loop is `plant` (a servo band's
    plant, servo/band.py): residual_servo(p) is this with plant = model = p."""
    return _residual(plant, compensation_filter(model, sample_period_s), sample_period_s)


def _residual(p: ServoParams, comp: DiscreteServo, sample_period_s: float) -> DiscreteServo:
    plant = discretise(p, sample_period_s)
    diff = np.array([1.0, -1.0]) / sample_period_s
    # H (1 + diff Y) - Y over the common denominator aH aY.
    num = _padd(np.convolve(plant.b, _padd(comp.a, np.convolve(diff, comp.b))),
                -np.convolve(comp.b, plant.a))
    return _fraction(num, np.convolve(plant.a, comp.a), sample_period_s)


class Precompensator:
    """The motion loop's streaming form: wanted positions in, frames to send out, per axis.

    Positions are mm, one row per sample and one column per axis; only the axes with a servo
    model are compensated (an axis given None passes through)."""

    def __init__(self, servos: list[ServoParams | None], sample_period_s: float,
                 start_mm: np.ndarray) -> None:
        self.filters = [None if p is None else compensation_filter(p, sample_period_s)
                        for p in servos]
        self.period_s = sample_period_s
        self.last_mm = np.asarray(start_mm, float).copy()
        # The compensated axes' filters run together: one call a push, not one per axis.
        self.axes = [i for i, f in enumerate(self.filters) if f is not None]
        self.all_axes = self.axes == list(range(len(self.filters)))
        self.stacked = StackedFilter([f for f in self.filters if f is not None]) \
            if self.axes else None
        self.lead_mm = np.zeros(len(self.filters))

    def push(self, wanted_mm: np.ndarray) -> np.ndarray:
        """Frames for the next wanted rows (same shape)."""
        if not len(wanted_mm):
            return wanted_mm
        wanted_mm = np.asarray(wanted_mm, float)
        # np.diff of np.vstack, as two subtractions (the same values, a third of the calls).
        d = np.empty(wanted_mm.shape)
        np.subtract(wanted_mm[0], self.last_mm, out=d[0])
        np.subtract(wanted_mm[1:], wanted_mm[:-1], out=d[1:])
        v = d / self.period_s
        out = wanted_mm.copy()
        if self.stacked is not None:
            if self.all_axes:  # no column picked out (a copy each) when every axis is
                lead = self.stacked.step(v)
                out += lead
                self.lead_mm = lead[-1].copy()
            else:
                lead = self.stacked.step(v[:, self.axes])
                out[:, self.axes] += lead
                self.lead_mm[self.axes] = lead[-1]
        self.last_mm = wanted_mm[-1].copy()
        return out

    def settling_rows(self) -> np.ndarray:
        """Frames at the standstill that follow until the lead has died away (held wanted
        position): without them the card would stop a lead away from the path."""
        rows: list[np.ndarray] = []
        still = np.repeat(self.last_mm[None, :], 16, axis=0)
        while np.abs(self.lead_mm).max() > SETTLED_LEAD_MM and len(rows) * 16 < MAX_SETTLE_FRAMES:
            rows.append(self.push(still))
        return np.vstack(rows) if rows else np.zeros((0, len(self.last_mm)))

    def to_rest(self, wanted_mm: np.ndarray) -> np.ndarray:
        """Every frame a stream of wanted rows ending at rest is sent as: push, then the
        settling (what the motion loop sends for a whole program)."""
        return np.vstack([self.push(wanted_mm), self.settling_rows()])

    def state(self) -> tuple:
        filt = None if self.stacked is None else self.stacked.state.copy()
        return self.last_mm.copy(), filt, self.lead_mm.copy()

    def restore(self, state: tuple) -> None:
        last, filt, lead = state
        self.last_mm, self.lead_mm = last.copy(), lead.copy()
        if self.stacked is not None:
            self.stacked.state = filt.copy()
