"""PH quintic replacement of a curve zone (paper 4.3, Table I): Hermite fit, error, bisection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from controller.geometry.curves import Curve
from controller.geometry.ph_quintic import PhQuintic
from controller.numeric import clamp

_ERROR_SAMPLES = 257
_FOOT_NEWTON_SWEEPS = 8
# Newton converges quadratically: a last step of 1e-6 of the range leaves ~1e-12 after the
# linear correction below, while the next sweep (a whole curve evaluation) would only confirm it.
FOOT_SETTLED = 1e-6
DEFAULT_MAX_DEPTH = 8


@dataclass(frozen=True, eq=False)
class PhSegment:
    """A PH quintic standing in for the curve on [u_start, u_end], with its fit error (mm)."""

    u_start: float
    u_end: float
    ph: PhQuintic
    fit_rms_mm: float
    fit_max_mm: float


def _complex(xy: np.ndarray) -> complex:
    return complex(xy[0], xy[1])


def _hermite_all(curve: Curve, u_start: np.ndarray, u_end: np.ndarray) -> list[PhQuintic]:
    """For each zone (docs/algorithms.md, PH quintic blends): p0 = C(u_s), p5 = C(u_e),
    d = C'(u) (u_e - u_s) (xi-derivatives), with one curve evaluation for all the zones' ends."""
    d = curve.evaluate(np.concatenate((u_start, u_end)), 1)
    n, du = len(u_start), u_end - u_start
    return [PhQuintic.hermite(_complex(d[0, i]), _complex(d[0, n + i]),
                              _complex(d[1, i]) * du[i], _complex(d[1, n + i]) * du[i])
            for i in range(n)]


def foot_distances(curve: Curve, u_start: ArrayLike, u_end: ArrayLike, pts: np.ndarray,
                   u_guess: np.ndarray) -> np.ndarray:
    """Distance from each point to the curve on [u_start, u_end] (per point or shared): Newton
    on C'.(C - P) = 0, stopped once no step moves u by more than FOOT_SETTLED of its range."""
    u = u_guess.copy()
    lo, hi = np.broadcast_to(u_start, u.shape), np.broadcast_to(u_end, u.shape)
    settled = FOOT_SETTLED * np.maximum(hi - lo, 1e-300)
    px, py = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
    rows = getattr(curve, "evaluate_rows", None) or \
        (lambda uu, order: curve.evaluate(uu, order).transpose(0, 2, 1))
    for _ in range(_FOOT_NEWTON_SWEEPS):
        # x and y rows apart: the dot products as einsum over (x, y) computed them, the
        # same sums in the same order, without strided reads
        (cx, cy), (d1x, d1y), (d2x, d2y) = rows(u, 2)
        dx, dy = cx - px, cy - py
        f = d1x * dx + d1y * dy
        fp = (d1x * d1x + d1y * d1y) + (d2x * dx + d2y * dy)
        step = np.where(fp > 0, f / np.where(fp > 0, fp, 1.0), 0.0)
        u_new = clamp(u - step, lo, hi)
        moved = u - u_new
        if not np.any(np.abs(moved) > settled):
            # Settled: C(u_new) = C(u) - moved C'(u) up to moved^2 |C''| / 2, ~1e-12 of the
            # zone's size, so the distance at the foot needs no further curve evaluation.
            dx -= moved * d1x
            dy -= moved * d1y
            return np.sqrt(dx * dx + dy * dy)
        u = u_new
    return np.linalg.norm(curve.evaluate(u, 0)[0] - pts, axis=1)


def _points(phs: list[PhQuintic], xi: np.ndarray) -> np.ndarray:
    """Every PH's points at xi, (len(phs), xi.size): PhQuintic.point's Horner scheme run on
    all of them at once, the same operations on each element (the same numbers)."""
    c = np.array([ph._r_power for ph in phs])  # noqa: SLF001 (lowest power first)
    acc = c[:, -1, None] * xi + c[:, -2, None]
    for k in range(c.shape[1] - 3, -1, -1):
        acc *= xi
        acc += c[:, k, None]
    return acc


def _fit_all(curve: Curve, u_start: np.ndarray, u_end: np.ndarray) -> list[PhSegment]:
    """fit_single for many zones at once: one batch of foot-point sweeps for all their samples."""
    phs = _hermite_all(curve, u_start, u_end)
    xi = np.linspace(0.0, 1.0, _ERROR_SAMPLES)
    z = _points(phs, xi).ravel()
    lo, hi = np.repeat(u_start, xi.size), np.repeat(u_end, xi.size)
    dist = foot_distances(curve, lo, hi, np.column_stack((z.real, z.imag)),
                          lo + np.tile(xi, len(phs)) * (hi - lo)).reshape(len(phs), xi.size)
    rms = np.sqrt(np.mean(dist**2, axis=1))
    worst = dist.max(axis=1)
    return [PhSegment(float(u_start[i]), float(u_end[i]), phs[i], float(rms[i]), float(worst[i]))
            for i in range(len(phs))]


def fit_single(curve: Curve, u_start: float, u_end: float) -> PhSegment:
    """One PH quintic on the whole zone: the 'without division' column of Table I."""
    return _fit_all(curve, np.array([u_start]), np.array([u_end]))[0]


def fit_zone(curve: Curve, u_start: float, u_end: float, error_limit_mm: float,
             max_depth: int = DEFAULT_MAX_DEPTH) -> list[PhSegment]:
    """Bisect the zone in u until every piece's RMS error is <= error_limit_mm (Table I)."""
    return fit_zones(curve, [(u_start, u_end)], error_limit_mm, max_depth)[0]


def fit_zones(curve: Curve, zones: list[tuple[float, float]], error_limit_mm: float,
              max_depth: int = DEFAULT_MAX_DEPTH) -> list[list[PhSegment]]:
    """fit_zone for several zones of one curve, breadth first: all pieces of one bisection
    level, of every zone, are fitted in one batch."""
    done: list[list[PhSegment]] = [[] for _ in zones]
    lo = np.array([z[0] for z in zones], float)
    hi = np.array([z[1] for z in zones], float)
    owner = np.arange(len(zones))
    for depth in range(max_depth + 1):
        if owner.size == 0:
            break
        segs = _fit_all(curve, lo, hi)
        split = np.array([seg.fit_rms_mm > error_limit_mm and depth < max_depth
                          for seg in segs], bool)
        for i in np.flatnonzero(~split).tolist():
            done[owner[i]].append(segs[i])
        a, b, owner = lo[split], hi[split], owner[split]
        mid = 0.5 * (a + b)
        lo, hi, owner = np.concatenate((a, mid)), np.concatenate((mid, b)), np.tile(owner, 2)
    return [sorted(d, key=lambda seg: seg.u_start) for d in done]


@dataclass(frozen=True, eq=False)
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
