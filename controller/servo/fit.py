"""Fit the eq. 27 loop of one axis to a recorded excitation: output-error least squares.

The measured tracking error e = r - p (commanded minus encoder position, per sample) is
compared with the model's, simulated from the commanded velocity exactly as the planner
predicts it (`discretise`, the ZOH form of E/V). Output error rather than an equation-error
(ARX) fit: the encoder's quantisation is noise on the output, which biases an ARX fit's poles
but not an output-error one. Levenberg-Marquardt on six parameters, started from the model in
force: ln a0..ln a3 (positive, and of very different sizes), and a1 - b1, a2 - b2 (the
numerator of E/V, scaled by their starting values; small differences of large numbers, which
is why they are the parameters and not b1, b2). a4 = 1 and b0 = a0 (the loop tracks a constant
position). A step that makes the model unusable (`servo_poles.pole_problem`) is refused.

The record is split in time: the first FIT_SHARE of it is fitted, the rest (held out, simulated
on from the fitted part's end) gives the fit's quality, as NRMSE and fit % = 100 (1 - NRMSE).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.config import ServoParams
from controller.servo.model import DiscreteServo, error_transfer, filter_block, zoh
from controller.servo_poles import pole_problem

FIT_SHARE = 0.7
MAX_ITERATIONS = 60
FD_STEP = 1e-6  # relative finite-difference step on the (scaled) parameters


@dataclass(frozen=True)
class AxisFit:
    """The identified loop and how well it and the model in force explain the held-out data."""

    params: ServoParams
    fit_pct: float  # identified model on the held-out part
    fit_pct_in_force: float  # the model in force on the same part
    rms_um: float  # identified model's residual on the held-out part
    problem: str | None  # why the identified model is unusable (None: it is usable)
    iterations: int


def params_of(theta: np.ndarray, scale: np.ndarray) -> ServoParams:
    a0, a1, a2, a3 = np.exp(theta[:4])
    n0, n1 = theta[4:] * scale
    return ServoParams(a0=float(a0), a1=float(a1), a2=float(a2), a3=float(a3), a4=1.0,
                       b0=float(a0), b1=float(a1 - n0), b2=float(a2 - n1))


def _theta_of(p: ServoParams) -> tuple[np.ndarray, np.ndarray]:
    n0, n1 = (p.a1 - p.b1) / p.a4, (p.a2 - p.b2) / p.a4
    scale = np.array([abs(n0) or 0.02 * p.a1 / p.a4, abs(n1) or 0.2 * p.a2 / p.a4])
    coeffs = np.array([p.a0, p.a1, p.a2, p.a3]) / p.a4
    return np.r_[np.log(coeffs), np.array([n0, n1]) / scale], scale


def simulate_error_mm(p: ServoParams, v_mm_s: np.ndarray, sample_period_s: float) -> np.ndarray:
    """The model's tracking error for per-sample velocities from rest (no cache: a fit asks
    for hundreds of parameter sets once each)."""
    b, a = zoh(*error_transfer(p), sample_period_s)
    servo = DiscreteServo(b=b / a[0], a=a / a[0], sample_period_s=sample_period_s)
    return filter_block(servo, np.asarray(v_mm_s, float), np.zeros(servo.order))[0]


def usable(p: ServoParams, sample_period_s: float) -> str | None:
    """Why a fitted model cannot be planned with (None: it can)."""
    if not all(np.isfinite([p.a0, p.a1, p.a2, p.a3, p.b1, p.b2])):
        return "the fit diverged (coefficients not finite)"
    if p.b1 <= 0 or p.b2 <= 0:
        return f"b1 = {p.b1:.4g}, b2 = {p.b2:.4g}: a config needs them positive"
    return pole_problem([p.a4, p.a3, p.a2, p.a1, p.a0], sample_period_s)


def fit_pct(measured: np.ndarray, model: np.ndarray) -> float:
    """100 (1 - NRMSE): 100 a perfect fit, 0 no better than the mean, negative worse."""
    spread = float(np.linalg.norm(measured - measured.mean()))
    if spread == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(measured - model)) / spread)


def fit_axis(commanded_mm: np.ndarray, measured_mm: np.ndarray, start: ServoParams,
             sample_period_s: float, rest_samples: int = 0,
             measured_index: np.ndarray | None = None) -> AxisFit:
    """Fit the loop to one axis's record: the commanded position of every sample, and the
    encoder's at the samples measured_index (default: every sample; a serial card reports
    some only). At rest for its first rest_samples samples, whose mean error is the encoder's
    offset."""
    r = np.asarray(commanded_mm, float)
    idx = np.arange(len(r)) if measured_index is None else np.asarray(measured_index, int)
    if len(idx) != len(measured_mm) or len(idx) < 10 or idx.min() < 0 or idx.max() >= len(r):
        raise ValueError("the measured samples do not match the commanded ones")
    e_meas = r[idx] - np.asarray(measured_mm, float)
    if rest_samples > 0 and np.any(idx < rest_samples):
        e_meas = e_meas - e_meas[idx < rest_samples].mean()
    v = np.diff(r, prepend=r[:1]) / sample_period_s
    n_fit = int(len(r) * FIT_SHARE)
    fit_rows = idx < n_fit
    i_fit, e_fit_meas = idx[fit_rows], e_meas[fit_rows]
    theta, scale = _theta_of(start)

    def residual(th: np.ndarray) -> np.ndarray | None:
        p = params_of(th, scale)
        if usable(p, sample_period_s) is not None:
            return None
        with np.errstate(all="ignore"):
            res = simulate_error_mm(p, v[:n_fit], sample_period_s)[i_fit] - e_fit_meas
        return res if np.all(np.isfinite(res)) else None

    res = residual(theta)
    if res is None:
        raise ValueError("the model in force is not a usable starting point")
    cost, lam, it = float(res @ res), 1e-3, 0
    for it in range(1, MAX_ITERATIONS + 1):  # noqa: B007 (the count is reported)
        jac = np.empty((len(i_fit), len(theta)))
        for j in range(len(theta)):
            step = np.zeros_like(theta)
            step[j] = FD_STEP * max(1.0, abs(theta[j]))
            r_j = residual(theta + step)
            if r_j is None:
                r_j = res - (residual(theta - step) - res) if residual(theta - step) is not None \
                    else res
            jac[:, j] = (r_j - res) / step[j]
        jtj, jtr = jac.T @ jac, jac.T @ res
        improved = False
        while lam < 1e12:
            delta = np.linalg.solve(jtj + lam * np.diag(np.diag(jtj) + 1e-30), -jtr)
            trial = residual(theta + delta)
            if trial is not None and float(trial @ trial) < cost:
                gain = cost - float(trial @ trial)
                theta, res, cost = theta + delta, trial, float(trial @ trial)
                lam = max(lam / 3.0, 1e-12)
                improved = True
                break
            lam *= 4.0
        if not improved or gain < 1e-10 * cost:
            break
    params = params_of(theta, scale)
    e_fit = simulate_error_mm(params, v, sample_period_s)[idx]
    e_force = simulate_error_mm(start, v, sample_period_s)[idx]
    held = ~fit_rows
    return AxisFit(params=params, fit_pct=fit_pct(e_meas[held], e_fit[held]),
                   fit_pct_in_force=fit_pct(e_meas[held], e_force[held]),
                   rms_um=1000.0 * float(np.sqrt(np.mean((e_meas[held] - e_fit[held]) ** 2))),
                   problem=usable(params, sample_period_s), iterations=it)
