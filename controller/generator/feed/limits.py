"""Feed limits from path curvature: chord error (eq. 23), curvature feed (eq. 24), centripetal."""

from __future__ import annotations

import numpy as np


def _abs_kappa(kappa_per_mm: np.ndarray | float) -> np.ndarray:
    return np.abs(np.asarray(kappa_per_mm, dtype=float))


def chord_error_feed_mm_s(kappa_per_mm: np.ndarray | float, sample_period_s: float,
                          chord_tol_mm: float, vmax_mm_s: float) -> np.ndarray:
    """V_af = (2/T) sqrt(2 delta/kappa - delta^2) (eq. 23), capped by Vmax.

    The chord formula c = 2 sqrt(2 rho delta - delta^2) holds for rho >= delta (c = 2 rho at
    rho = delta). For rho < delta the sagitta never reaches delta, so the chord is bounded by the
    diameter: we use c = 2 rho there, continuous and monotone, instead of the formula's square root
    of a negative number. kappa -> 0 gives an unbounded V_af, i.e. Vmax.
    """
    k = _abs_kappa(kappa_per_mm)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        rho = np.where(k > 0.0, 1.0 / np.where(k > 0.0, k, 1.0), np.inf)
        formula = np.sqrt(np.maximum(2.0 * rho * chord_tol_mm - chord_tol_mm ** 2, 0.0))
        chord = np.where(rho >= chord_tol_mm, 2.0 * formula, 2.0 * rho)
    return np.minimum(chord / sample_period_s, vmax_mm_s)


def curvature_feed_mm_s(kappa_per_mm: np.ndarray | float, kappa_bar_per_mm: float,
                        vmax_mm_s: float) -> np.ndarray:
    """V_cf = kappa_bar / (kappa + kappa_bar) * Vmax (eq. 24); never above Vmax."""
    k = _abs_kappa(kappa_per_mm)
    return kappa_bar_per_mm / (k + kappa_bar_per_mm) * vmax_mm_s


def centripetal_feed_mm_s(kappa_per_mm: np.ndarray | float, accel_mm_s2: float,
                          vmax_mm_s: float) -> np.ndarray:
    """sqrt(Amax/kappa): normal acceleration kappa v^2 at most Amax; Vmax where kappa -> 0."""
    k = _abs_kappa(kappa_per_mm)
    with np.errstate(divide="ignore", over="ignore"):
        v = np.sqrt(accel_mm_s2 / k)
    return np.minimum(v, vmax_mm_s)


def corner_feed_mm_s(kappa_per_mm: np.ndarray | float, sample_period_s: float,
                     chord_tol_mm: float, kappa_bar_per_mm: float,
                     vmax_mm_s: float) -> np.ndarray:
    """V_sp = min(V_af, V_cf) (eq. 22), the paper's feed at sharp corners."""
    return np.minimum(chord_error_feed_mm_s(kappa_per_mm, sample_period_s, chord_tol_mm, vmax_mm_s),
                      curvature_feed_mm_s(kappa_per_mm, kappa_bar_per_mm, vmax_mm_s))


def path_feed_limit_mm_s(kappa_per_mm: np.ndarray | float, sample_period_s: float,
                         chord_tol_mm: float, accel_mm_s2: float,
                         vmax_mm_s: float) -> np.ndarray:
    """min(Vmax, sqrt(Amax/kappa), V_af): the limit of the time-optimal bound (docs/algorithms.md,
    Feed planning)."""
    return np.minimum(chord_error_feed_mm_s(kappa_per_mm, sample_period_s, chord_tol_mm, vmax_mm_s),
                      centripetal_feed_mm_s(kappa_per_mm, accel_mm_s2, vmax_mm_s))
