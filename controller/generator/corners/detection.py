"""Sharp corner detection (paper eqs. 13-15): curvature peaks above kappa_th and their zones."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from controller.geometry.curves import (
    Curve,
    curvature_and_derivative_from_rows,
    curvature_derivative_from_derivatives,
    curvature_from_derivatives,
)
from controller.numeric import is_in_sorted, sorted_unique

_XTOL = 1e-13
# A curvature peak is located exactly only where the grid's curvature beside it reaches this
# share of kappa_th: on a grid of 64 samples per knot span a peak's neighbours are within a few
# per cent of it, so a peak below half the threshold there cannot be a sharp corner, and most
# of a section's gentle peaks (12 of the airfoil's 13) are not root-found for nothing.
PEAK_PREFILTER = 0.5


@dataclass(frozen=True, eq=False)
class CornerZone:
    """Parameter interval [u_start, u_end] around the curvature peak u_peak (Figure 1's AB, CD)."""

    u_start: float
    u_end: float
    u_peak: float
    kappa_peak_per_mm: float


def sample_grid(curve: Curve, samples_per_span: int = 64) -> np.ndarray:
    """Parameters to scan: samples_per_span per knot span (NURBS) or a uniform grid otherwise."""
    knots = getattr(curve, "knots", None)
    if knots is None:
        return np.linspace(curve.u_start, curve.u_end, 8 * samples_per_span + 1)
    inner = sorted_unique(knots[(knots >= curve.u_start) & (knots <= curve.u_end)])
    frac = np.arange(samples_per_span) / samples_per_span
    grid = (inner[:-1, None] + np.diff(inner)[:, None] * frac[None, :]).ravel()
    return np.append(grid, inner[-1])


def _kappa_and_slope(curve: Curve, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """kappa and dkappa/du on a grid from one evaluation of the first three derivatives."""
    rows = getattr(curve, "evaluate_rows", None)
    if rows is not None:
        return curvature_and_derivative_from_rows(rows(u, 3))
    d = curve.evaluate(u, 3)
    return curvature_from_derivatives(d), curvature_derivative_from_derivatives(d)


def _kappa(curve: Curve, u: float) -> float:
    """Unsigned curvature at one u, without numpy (root finding calls this one point at a time)."""
    dx, dy, ddx, ddy = curve.derivatives_scalar(u)
    speed2 = dx * dx + dy * dy
    if speed2 == 0.0:
        return float(curve.curvature(u)[0])  # the vectorised form's handling of a stop
    return abs(dx * ddy - dy * ddx) / speed2**1.5


def _dkappa(curve: Curve, u: float) -> float:
    return float(curve.curvature_derivative(u)[0])


def brentq(f: Callable[[float], float], lo: float, hi: float, xtol: float = _XTOL) -> float:
    """Root of f in [lo, hi] (f(lo), f(hi) of opposite signs) by the Illinois method.

    A small stand-in for scipy's brentq: scipy.optimize costs half a second to import, which
    `cncctl run` pays before the first motion."""
    flo, fhi = f(lo), f(hi)
    if flo == 0.0:
        return lo
    if fhi == 0.0:
        return hi
    side = 0
    xtol = xtol * max(1.0, abs(lo), abs(hi))  # relative for large parameters (knots ~ 1e2)
    for _ in range(200):
        x = (lo * fhi - hi * flo) / (fhi - flo)
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
        fx = f(x)
        if fx == 0.0 or hi - lo <= xtol:
            return x
        if (fx > 0) == (fhi > 0):
            hi, fhi = x, fx
            if side == 1:
                flo *= 0.5
            side = 1
        else:
            lo, flo = x, fx
            if side == -1:
                fhi *= 0.5
            side = -1
        if hi - lo <= xtol:
            break
    return 0.5 * (lo + hi)


def _bisect_all(f: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray,
                xtol: float = _XTOL, f_lo: np.ndarray | None = None,
                f_hi: np.ndarray | None = None) -> np.ndarray:
    """Roots of f in every bracket [lo_i, hi_i] at once (f(lo) > 0 >= f(hi)): the Illinois
    method vectorised (both ends move, so every bracket shrinks to xtol in a handful of
    steps), one curve evaluation per step for all brackets together. f_lo and f_hi, when
    known, save the first evaluation."""
    lo, hi = lo.astype(float).copy(), hi.astype(float).copy()
    if not lo.size:
        return lo
    f_lo = f(lo) if f_lo is None else np.asarray(f_lo, float).copy()
    f_hi = f(hi) if f_hi is None else np.asarray(f_hi, float).copy()
    # Relative to the parameter's size too: knots in the hundreds cannot be split to 1e-13.
    tol = xtol * np.maximum(1.0, np.maximum(np.abs(lo), np.abs(hi)))
    side = np.zeros(lo.size)  # +1: hi moved last, -1: lo moved last
    for _ in range(200):
        open_ = hi - lo > tol
        if not np.any(open_):
            break
        with np.errstate(divide="ignore", invalid="ignore"):
            x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        x = np.where((x > lo) & (x < hi), x, 0.5 * (lo + hi))
        fx = f(x)
        exact = fx == 0.0
        right = (fx <= 0.0) & open_  # the root is left of x: x becomes hi
        left = (fx > 0.0) & open_
        f_lo = np.where(right & (side == 1), 0.5 * f_lo, f_lo)  # Illinois: halve the stale end
        f_hi = np.where(left & (side == -1), 0.5 * f_hi, f_hi)
        hi, f_hi = np.where(right, x, hi), np.where(right, fx, f_hi)
        lo, f_lo = np.where(left, x, lo), np.where(left, fx, f_lo)
        lo = np.where(exact & open_, x, lo)
        side = np.where(right, 1, np.where(left, -1, side))
    return 0.5 * (lo + hi)


def _illinois(f: Callable[[float], float], lo: float, hi: float, f_lo: float, f_hi: float,
              xtol: float = _XTOL) -> float:
    """_bisect_all for one bracket in Python floats: the same steps and the same numbers (each
    bracket of _bisect_all moves on its own), without a dozen numpy calls on one element per
    step. A zero denominator is numpy's inf or nan there: not inside, so the midpoint."""
    tol = xtol * max(1.0, max(abs(lo), abs(hi)))
    side = 0  # +1: hi moved last, -1: lo moved last
    for _ in range(200):
        if not hi - lo > tol:
            break
        den = f_hi - f_lo
        x = (lo * f_hi - hi * f_lo) / den if den != 0.0 else math.nan
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
        fx = f(x)
        if fx <= 0.0:  # the root is left of x: x becomes hi
            if side == 1:
                f_lo = 0.5 * f_lo  # Illinois: halve the stale end
            hi, f_hi, side = x, fx, 1
            if fx == 0.0:
                lo = x
        elif fx > 0.0:
            if side == -1:
                f_hi = 0.5 * f_hi
            lo, f_lo, side = x, fx, -1
    return 0.5 * (lo + hi)


SCALAR_BRACKETS = 8  # up to this many peaks, dkappa/du point by point beats one numpy call


def _roots(curve: Curve, lo: np.ndarray, hi: np.ndarray, f_lo: np.ndarray,
           f_hi: np.ndarray) -> np.ndarray:
    """dkappa/du = 0 in every bracket: point by point in Python floats when there are few
    brackets and the curve has a scalar form (a numpy evaluation costs ~50 us whatever its
    size; one point ~8 us), else _bisect_all on arrays. The same roots either way."""
    scalar = getattr(curve, "curvature_derivative_scalar", None)
    if scalar is None or lo.size > SCALAR_BRACKETS:
        return _bisect_all(curve.curvature_derivative, lo, hi, f_lo=f_lo, f_hi=f_hi)
    return np.array([_illinois(scalar, a, b, fa, fb) for a, b, fa, fb in
                     zip(lo.tolist(), hi.tolist(), f_lo.tolist(), f_hi.tolist(), strict=True)])


def _peaks(curve: Curve, grid: np.ndarray, kappa: np.ndarray, dk: np.ndarray,
           floor: float = 0.0) -> list[float]:
    """Local maxima of kappa: dkappa/du = 0 going + to - (eq. 13), or at an end; inner ones
    only where the grid's kappa beside them reaches floor."""
    i = np.flatnonzero((dk[:-1] > 0) & (dk[1:] <= 0)
                       & (np.maximum(kappa[:-1], kappa[1:]) >= floor))
    lo, hi, f_lo, f_hi = grid[i], grid[i + 1], dk[i], dk[i + 1].copy()
    # dkappa/du jumps at a knot (the third derivative does); the grid holds the knots and dk
    # there is the value from the right. Seen from the left, a knot where dkappa/du is still
    # rising is a kink peak: the maximum is the knot itself. Elsewhere the left value is the
    # bracket's end value.
    knots = getattr(curve, "knots", None)
    at_knot = np.flatnonzero(is_in_sorted(hi, knots)) if knots is not None else np.empty(0, int)
    kink = np.zeros(i.size, bool)
    if at_knot.size:
        left = curve.curvature_derivative(np.nextafter(hi[at_knot], -np.inf))
        kink[at_knot] = left > 0
        f_hi[at_knot] = np.where(left > 0, f_hi[at_knot], left)
    roots = hi.copy()
    smooth = ~kink
    roots[smooth] = _roots(curve, lo[smooth], hi[smooth], f_lo[smooth], f_hi[smooth])
    peaks = roots.tolist()
    if dk[0] < 0:
        peaks.insert(0, float(grid[0]))
    if dk[-1] > 0:
        peaks.append(float(grid[-1]))
    return peaks


def _boundary(curve: Curve, grid: np.ndarray, kappa: np.ndarray, u_peak: float, level: float,
              direction: int) -> float:
    """Where kappa first falls to level going from u_peak in direction (-1 left, +1 right)."""
    if direction < 0:
        idx = np.nonzero((grid < u_peak) & (kappa <= level))[0]
        if idx.size == 0:
            return float(grid[0])
        lo, hi = float(grid[idx[-1]]), min(float(grid[idx[-1] + 1]), u_peak)
    else:
        idx = np.nonzero((grid > u_peak) & (kappa <= level))[0]
        if idx.size == 0:
            return float(grid[-1])
        lo, hi = max(float(grid[idx[0] - 1]), u_peak), float(grid[idx[0]])
    f = lambda u: _kappa(curve, u) - level  # noqa: E731
    if f(lo) * f(hi) > 0:
        return lo if direction < 0 else hi
    return float(brentq(f, lo, hi, xtol=_XTOL))


def _merge(zones: list[CornerZone]) -> list[CornerZone]:
    """Peaks sharing one above-threshold region give one zone, keeping the highest peak."""
    merged: list[CornerZone] = []
    for z in sorted(zones, key=lambda z: z.u_start):
        if merged and z.u_start <= merged[-1].u_end:
            last = merged.pop()
            top = z if z.kappa_peak_per_mm > last.kappa_peak_per_mm else last
            z = CornerZone(min(last.u_start, z.u_start), max(last.u_end, z.u_end),
                           top.u_peak, top.kappa_peak_per_mm)
        merged.append(z)
    return merged


def detect_sharp_corners(curve: Curve, kappa_th_per_mm: float,
                         samples_per_span: int = 64) -> list[CornerZone]:
    """Curvature maxima above kappa_th (eqs. 13, 15), each with its zone where kappa > kappa_th."""
    grid = sample_grid(curve, samples_per_span)
    kappa, dk = _kappa_and_slope(curve, grid)
    zones = []
    for u_peak in _peaks(curve, grid, kappa, dk, PEAK_PREFILTER * kappa_th_per_mm):
        k_peak = _kappa(curve, u_peak)
        if k_peak <= kappa_th_per_mm:
            continue
        u0 = _boundary(curve, grid, kappa, u_peak, kappa_th_per_mm, -1)
        u1 = _boundary(curve, grid, kappa, u_peak, kappa_th_per_mm, +1)
        zones.append(CornerZone(u0, u1, u_peak, k_peak))
    return _merge(zones)


def _widen_side(curve: Curve, grid: np.ndarray, kappa: np.ndarray, dk: np.ndarray,
                u_from: float, level: float, direction: int) -> float:
    """Walk outwards from u_from; stop where kappa < level or at a kappa minimum."""
    rising_back = dk <= 0 if direction < 0 else dk >= 0  # kappa grows again: past a minimum
    side = grid < u_from if direction < 0 else grid > u_from
    stop = np.nonzero(side & ((kappa < level) | rising_back))[0]
    if stop.size == 0:
        return float(grid[0] if direction < 0 else grid[-1])
    i = stop[-1] if direction < 0 else stop[0]
    lo, hi = sorted((float(grid[i]), float(grid[i - direction])))
    lo, hi = (lo, min(hi, u_from)) if direction < 0 else (max(lo, u_from), hi)
    if kappa[i] < level:
        f = lambda u: _kappa(curve, u) - level  # noqa: E731
    else:
        f = lambda u: _dkappa(curve, u)  # noqa: E731
    if lo >= hi or f(lo) * f(hi) > 0:
        return float(grid[i])
    return float(brentq(f, lo, hi, xtol=_XTOL))


def widen_zone(curve: Curve, zone: CornerZone, kappa_level: float,
               samples_per_span: int = 64) -> CornerZone:
    """The interval around u_peak where kappa > kappa_level, never past a kappa local minimum."""
    grid = sample_grid(curve, samples_per_span)
    kappa, dk = _kappa_and_slope(curve, grid)
    u0 = _widen_side(curve, grid, kappa, dk, zone.u_start, kappa_level, -1)
    u1 = _widen_side(curve, grid, kappa, dk, zone.u_end, kappa_level, +1)
    return CornerZone(min(u0, zone.u_start), max(u1, zone.u_end), zone.u_peak,
                      zone.kappa_peak_per_mm)


def joint_angle_rad(tangent_in: np.ndarray, tangent_out: np.ndarray) -> float:
    """Turning angle in [0, pi] between the incoming and outgoing tangents at a block joint."""
    cross = tangent_in[0] * tangent_out[1] - tangent_in[1] * tangent_out[0]
    dot = tangent_in[0] * tangent_out[0] + tangent_in[1] * tangent_out[1]
    return math.atan2(abs(cross), dot)
