"""Reference points on many PH quintics at once: eq. 12's Newton iteration over all samples."""

from __future__ import annotations

import numpy as np

from controller.geometry.ph_quintic import MAX_EXTRA_SWEEPS, NEWTON_SWEEPS, NEWTON_TOL_MM, PhQuintic


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
    for sweep in range(NEWTON_SWEEPS + MAX_EXTRA_SWEEPS):
        err = _horner_rows(s_pow, xi) - s
        if sweep >= NEWTON_SWEEPS and not np.any(np.abs(err) >= NEWTON_TOL_MM):
            break
        sigma = _horner_rows(sigma_pow, xi)
        step = np.divide(err, sigma, out=np.zeros_like(xi), where=sigma > 0)
        xi = np.clip(xi - step, 0.0, 1.0)
    r = _horner_rows(np.array([ph._r_power for ph in phs])[which], xi)
    w = np.array([[ph.w0, ph.w1, ph.w2] for ph in phs])[which]
    m = 1.0 - xi
    hodograph = (w[:, 0] * m * m + 2.0 * w[:, 1] * m * xi + w[:, 2] * xi * xi) ** 2
    return np.column_stack((r.real, r.imag)), np.arctan2(hodograph.imag, hodograph.real)
