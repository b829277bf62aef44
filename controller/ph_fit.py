"""PH quintic replacement of a curve zone (paper 4.3, Table I): Hermite fit, error, bisection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.curves import Curve
from controller.ph_quintic import PhQuintic

_ERROR_SAMPLES = 257
_FOOT_NEWTON_SWEEPS = 8
DEFAULT_MAX_DEPTH = 8


@dataclass(frozen=True)
class PhSegment:
    """A PH quintic standing in for the curve on [u_start, u_end], with its fit error (mm)."""

    u_start: float
    u_end: float
    ph: PhQuintic
    fit_rms_mm: float
    fit_max_mm: float


def _complex(xy: np.ndarray) -> complex:
    return complex(xy[0], xy[1])


def hermite_on_zone(curve: Curve, u_start: float, u_end: float) -> PhQuintic:
    """ALGORITHMS 1.3: p0 = C(u_s), p5 = C(u_e), d = C'(u) (u_e - u_s) (xi-derivatives)."""
    d = curve.evaluate(np.array([u_start, u_end]), 1)
    du = u_end - u_start
    return PhQuintic.hermite(_complex(d[0, 0]), _complex(d[0, 1]),
                             _complex(d[1, 0]) * du, _complex(d[1, 1]) * du)


def foot_distances(curve: Curve, u_start: float, u_end: float, pts: np.ndarray,
                   u_guess: np.ndarray) -> np.ndarray:
    """Distance from each point to the curve on [u_start, u_end]: Newton on C'.(C - P) = 0."""
    u = u_guess.copy()
    for _ in range(_FOOT_NEWTON_SWEEPS):
        d = curve.evaluate(u, 2)
        diff = d[0] - pts
        f = np.einsum("ni,ni->n", d[1], diff)
        fp = np.einsum("ni,ni->n", d[1], d[1]) + np.einsum("ni,ni->n", d[2], diff)
        step = np.where(fp > 0, f / np.where(fp > 0, fp, 1.0), 0.0)
        u = np.clip(u - step, u_start, u_end)
    return np.linalg.norm(curve.evaluate(u, 0)[0] - pts, axis=1)


def fit_error_mm(curve: Curve, u_start: float, u_end: float, ph: PhQuintic) -> tuple[float, float]:
    """RMS and max distance from densely sampled PH points to the curve zone."""
    xi = np.linspace(0.0, 1.0, _ERROR_SAMPLES)
    z = ph.point(xi)
    dist = foot_distances(curve, u_start, u_end, np.column_stack((z.real, z.imag)),
                          u_start + xi * (u_end - u_start))
    return float(np.sqrt(np.mean(dist**2))), float(dist.max())


def fit_single(curve: Curve, u_start: float, u_end: float) -> PhSegment:
    """One PH quintic on the whole zone: the 'without division' column of Table I."""
    ph = hermite_on_zone(curve, u_start, u_end)
    rms, worst = fit_error_mm(curve, u_start, u_end, ph)
    return PhSegment(u_start, u_end, ph, rms, worst)


def fit_zone(curve: Curve, u_start: float, u_end: float, error_limit_mm: float,
             max_depth: int = DEFAULT_MAX_DEPTH) -> list[PhSegment]:
    """Bisect the zone in u until every piece's RMS error is <= error_limit_mm (Table I)."""
    seg = fit_single(curve, u_start, u_end)
    if seg.fit_rms_mm <= error_limit_mm or max_depth <= 0:
        return [seg]
    mid = 0.5 * (u_start + u_end)
    return (fit_zone(curve, u_start, mid, error_limit_mm, max_depth - 1)
            + fit_zone(curve, mid, u_end, error_limit_mm, max_depth - 1))


@dataclass(frozen=True)
class ZoneFitReport:
    """Table I analogue for one zone: error of one PH and of the subdivided PH chain (mm)."""

    undivided_rms_mm: float
    undivided_max_mm: float
    divided_rms_mm: float
    divided_max_mm: float
    pieces: int


def zone_fit_report(curve: Curve, u_start: float, u_end: float,
                    error_limit_mm: float) -> ZoneFitReport:
    """Undivided and divided errors; divided RMS pools all pieces' samples (equal counts each)."""
    one = fit_single(curve, u_start, u_end)
    pieces = fit_zone(curve, u_start, u_end, error_limit_mm)
    rms = float(np.sqrt(np.mean([p.fit_rms_mm**2 for p in pieces])))
    return ZoneFitReport(one.fit_rms_mm, one.fit_max_mm, rms,
                         max(p.fit_max_mm for p in pieces), len(pieces))
