"""Reference-point interpolators: exact PH (eqs. 10-12, Newton) and Taylor NURBS (eq. 5)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from controller.curves import Curve
from controller.ph_quintic import PhQuintic

NEWTON_TOL_MM = 1e-9
_NEWTON_SWEEPS = 3  # from the 33-node table start: ~1e-4 L -> ~1e-8 L -> ~1e-12 -> round-off
_MAX_EXTRA_SWEEPS = 20


def _newton_sweep(ph: PhQuintic, xi: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Eq. 12 on the whole array, kept inside [0, 1]."""
    sigma = ph.sigma(xi)
    step = np.divide(ph.arc_length(xi) - s, sigma, out=np.zeros_like(xi), where=sigma > 0)
    return np.clip(xi - step, 0.0, 1.0)


def ph_interpolate(ph: PhQuintic, s_targets_mm: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Solve s(xi_k) = target_k for all k at once; returns (xi, |s(xi) - target| in mm).

    Start from linear interpolation in a coarse s(xi) table (s is monotone), then a fixed few
    vectorised Newton sweeps; extra sweeps only if some residual is still above 1e-9 mm.
    """
    s = np.clip(np.asarray(s_targets_mm, dtype=float), 0.0, ph.length_mm)
    table_xi, table_s = ph.arc_length_table
    xi = np.interp(s, table_s, table_xi)
    for _ in range(_NEWTON_SWEEPS):
        xi = _newton_sweep(ph, xi, s)
    residual = np.abs(ph.arc_length(xi) - s)
    extra = 0
    while residual.size and residual.max() >= NEWTON_TOL_MM and extra < _MAX_EXTRA_SWEEPS:
        xi, extra = _newton_sweep(ph, xi, s), extra + 1
        residual = np.abs(ph.arc_length(xi) - s)
    return xi, residual


def _horner_rows(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per-row polynomials (lowest coefficient first in each row of coeffs) at x."""
    acc = coeffs[:, -1] * x + coeffs[:, -2]
    for j in range(coeffs.shape[1] - 3, -1, -1):
        acc = acc * x + coeffs[:, j]
    return acc


def ph_interpolate_many(phs: list[PhQuintic], which: np.ndarray,
                        s_targets_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ph_interpolate for samples on many PH quintics at once: sample k lies on phs[which[k]]
    at arc length s_targets_mm[k]. Returns (points (N, 2), tangent angles) from the same
    Newton iteration, every polynomial evaluated with per-sample coefficients."""
    length = np.array([ph.length_mm for ph in phs])[which]
    s = np.clip(s_targets_mm, 0.0, length)
    s_pow = np.array([ph._s_power for ph in phs])[which]
    sigma_pow = np.array([ph._sigma_power for ph in phs])[which]
    # Start: each quintic's own 33-node table, searched at once (tables offset per quintic).
    tab_xi = phs[0].arc_length_table[0]
    tab_s = np.array([ph.arc_length_table[1] for ph in phs])
    big = 2.0 * float(tab_s.max()) + 1.0
    flat = (tab_s + big * np.arange(len(phs))[:, None]).ravel()
    j = np.clip(np.searchsorted(flat, s + big * which, side="right") - 1 - which * tab_xi.size,
                0, tab_xi.size - 2)
    s0, s1 = tab_s[which, j], tab_s[which, j + 1]
    ds = np.where(s1 > s0, s1 - s0, 1.0)
    xi = tab_xi[j] + (tab_xi[j + 1] - tab_xi[j]) * np.clip((s - s0) / ds, 0.0, 1.0)
    for sweep in range(_NEWTON_SWEEPS + _MAX_EXTRA_SWEEPS):
        err = _horner_rows(s_pow, xi) - s
        if sweep >= _NEWTON_SWEEPS and not np.any(np.abs(err) >= NEWTON_TOL_MM):
            break
        sigma = _horner_rows(sigma_pow, xi)
        step = np.divide(err, sigma, out=np.zeros_like(xi), where=sigma > 0)
        xi = np.clip(xi - step, 0.0, 1.0)
    r = _horner_rows(np.array([ph._r_power for ph in phs])[which], xi)
    w = np.array([[ph.w0, ph.w1, ph.w2] for ph in phs])[which]
    m = 1.0 - xi
    hodograph = (w[:, 0] * m * m + 2.0 * w[:, 1] * m * xi + w[:, 2] * xi * xi) ** 2
    return np.column_stack((r.real, r.imag)), np.arctan2(hodograph.imag, hodograph.real)


def taylor_step(curve: Curve, u: float, v_mm_s: float, a_mm_s2: float, T_s: float) -> float:
    """Eq. 5: u + V T/|C'| + T^2/2 (A/|C'| - V^2 (C'.C'')/|C'|^4)."""
    dx, dy, ddx, ddy = curve.derivatives_scalar(u)
    speed2 = dx * dx + dy * dy
    speed = math.sqrt(speed2)
    return (u + v_mm_s * T_s / speed
            + 0.5 * T_s * T_s * (a_mm_s2 / speed - v_mm_s * v_mm_s * (dx * ddx + dy * ddy)
                                 / (speed2 * speed2)))


def taylor_interpolate(curve: Curve, u0: float, v_mm_s: ArrayLike, a_mm_s2: ArrayLike,
                       T_s: float) -> np.ndarray:
    """u_0 .. u_N for N ticks of eq. 5 (sequential by nature); u is held at the curve's end."""
    v = np.asarray(v_mm_s, dtype=float).tolist()
    a = np.asarray(a_mm_s2, dtype=float).tolist()
    u_end = curve.u_end
    out = [float(u0)]
    u = float(u0)
    for vk, ak in zip(v, a, strict=True):
        if u < u_end:
            u = min(taylor_step(curve, u, vk, ak, T_s), u_end)
        out.append(u)
    return np.array(out)


@dataclass(frozen=True)
class FeedFluctuation:
    """Per-step |actual step - V T| / (V T): maximum, RMS and the whole series."""

    max_ratio: float
    rms_ratio: float
    per_step: np.ndarray


def feed_fluctuation(points: ArrayLike, v_mm_s: ArrayLike, T_s: float) -> FeedFluctuation:
    """points: (N+1,) arc-length positions (exact step = difference) or (N+1, 2) positions
    (step = chord). v_mm_s: the commanded feed of each of the N steps (scalar or (N,))."""
    p = np.asarray(points, dtype=float)
    step = np.diff(p) if p.ndim == 1 else np.linalg.norm(np.diff(p, axis=0), axis=1)
    nominal = np.broadcast_to(np.asarray(v_mm_s, dtype=float), step.shape) * T_s
    ratio = np.abs(step - nominal) / nominal
    return FeedFluctuation(float(ratio.max()), float(np.sqrt(np.mean(ratio**2))), ratio)
