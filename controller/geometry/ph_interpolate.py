"""Reference points on many PH quintics at once: eq. 12's Newton iteration over all samples."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.geometry.ph_quintic import (
    MAX_EXTRA_SWEEPS,
    NEWTON_SWEEPS,
    NEWTON_TOL_MM,
    PhQuintic,
    _bernstein_to_power_matrix,
)

_TABLE_XI = np.linspace(0.0, 1.0, 33)  # PhQuintic.arc_length_table's nodes


def _horner_rows(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per-row polynomials (lowest coefficient first in each row of coeffs) at x."""
    acc = coeffs[:, -1] * x + coeffs[:, -2]
    for j in range(coeffs.shape[1] - 3, -1, -1):
        acc = acc * x + coeffs[:, j]
    return acc


def _power(bernstein: np.ndarray) -> np.ndarray:
    """bernstein_to_power of every row: one matrix-vector product per power (a row of the
    conversion matrix), the BLAS kernel PhQuintic's own conversion uses, so each quintic's
    numbers bit for bit (tested), where a matrix product sums in another order. A single row
    is doubled: numpy takes a 1-row product for a dot product, which sums in another order."""
    rows = bernstein if len(bernstein) > 1 else np.repeat(bernstein, 2, axis=0)
    m = _bernstein_to_power_matrix(bernstein.shape[1] - 1)
    return np.stack([rows @ row for row in m], axis=1)[:len(bernstein)]


@dataclass(frozen=True, eq=False, repr=False)
class PowerForms:
    """What the Newton iteration needs of each quintic, computed for all of them at once with
    PhQuintic's own operations (its cached properties, one object at a time, were most of the
    interpolation of a G1 program with a blend at every joint)."""

    s_power: np.ndarray  # (m, 6) arc length
    sigma_power: np.ndarray  # (m, 5) parametric speed
    r_power: np.ndarray  # (m, 6) complex points
    w: np.ndarray  # (m, 3) complex
    table_s: np.ndarray  # (m, 33) arc length at _TABLE_XI


def _product(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(real, imaginary) of a * b as CPython multiplies two complex numbers (numpy's complex
    product may differ in the last bit)."""
    return a.real * b.real - a.imag * b.imag, a.real * b.imag + a.imag * b.real


def _complex(re: np.ndarray, im: np.ndarray) -> np.ndarray:
    """re + i im with signed zeros kept (re + 1j * im would turn an imaginary -0 into +0)."""
    z = np.empty(re.shape, complex)
    z.real, z.imag = re, im
    return z


def _over(re: np.ndarray, im: np.ndarray, d: float) -> np.ndarray:
    """(re + i im) / d as CPython divides a complex by a (real) int: Smith's method with a
    zero imaginary part, the same bits (signed zeros included) as PhQuintic's own."""
    return _complex((re + im * 0.0) / d, (im - re * 0.0) / d)


def control_rows(p0: np.ndarray, w: np.ndarray) -> np.ndarray:
    """PhQuintic.control_points of every row (p0 (m,), w (m, 3) complex) at once, with the
    same operations, so the same numbers bit for bit (tested)."""
    w0, w1, w2 = w[:, 0], w[:, 1], w[:, 2]
    two_w1 = _complex(2.0 * w1.real - 0.0 * w1.imag, 2.0 * w1.imag + 0.0 * w1.real)
    mid_re, mid_im = _product(two_w1, w1)
    cross_re, cross_im = _product(w0, w2)
    steps = np.column_stack((_over(*_product(w0, w0), 5.0), _over(*_product(w0, w1), 5.0),
                             _over(mid_re + cross_re, mid_im + cross_im, 15.0),
                             _over(*_product(w1, w2), 5.0), _over(*_product(w2, w2), 5.0)))
    out = np.zeros((len(p0), 6), complex)
    np.cumsum(steps, axis=1, out=out[:, 1:])
    return p0[:, None] + out


def power_forms(phs: list[PhQuintic]) -> PowerForms:
    """PowerForms from each quintic's Bernstein data, for all rows at once with PhQuintic's own
    operations (its sigma values are already computed for its length)."""
    sigma = np.array([ph.sigma_values for ph in phs]).reshape(-1, 5)
    arc = np.zeros((len(phs), 6))
    arc[:, 1:] = np.cumsum(sigma, axis=1) / 5.0
    coeffs = np.array([(ph.p0, ph.w0, ph.w1, ph.w2) for ph in phs], complex).reshape(-1, 4)
    w = coeffs[:, 1:]
    control = control_rows(coeffs[:, 0], w)
    s_power = _power(arc)
    table_s = s_power[:, 5:] * _TABLE_XI + s_power[:, 4:5]  # Horner, row by row
    for j in range(3, -1, -1):
        table_s = table_s * _TABLE_XI + s_power[:, j:j + 1]
    return PowerForms(s_power, _power(sigma), _power(control), w, table_s)


def ph_interpolate_many(phs: list[PhQuintic], which: np.ndarray,
                        s_targets_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ph_interpolate for samples on many PH quintics at once: sample k lies on phs[which[k]]
    at arc length s_targets_mm[k]. Returns (points (N, 2), tangent angles) from the same
    Newton iteration, every polynomial evaluated with per-sample coefficients."""
    forms = power_forms(phs)
    length = np.array([ph.length_mm for ph in phs])[which]
    s = np.clip(s_targets_mm, 0.0, length)
    s_pow = forms.s_power[which]
    sigma_pow = forms.sigma_power[which]
    # Start: each quintic's own 33-node table, searched at once (tables offset per quintic).
    tab_xi = _TABLE_XI
    tab_s = forms.table_s
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
    r = _horner_rows(forms.r_power[which], xi)
    w = forms.w[which]
    m = 1.0 - xi
    hodograph = (w[:, 0] * m * m + 2.0 * w[:, 1] * m * xi + w[:, 2] * xi * xi) ** 2
    return np.column_stack((r.real, r.imag)), np.arctan2(hodograph.imag, hodograph.real)
