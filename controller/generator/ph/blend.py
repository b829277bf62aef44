"""G1 corners between blocks: a PH quintic blend within the path tolerance (G64 P, else eps_max)."""

from __future__ import annotations

import math

import numpy as np

from controller.geometry.path import Piece, PieceKind, make_piece
from controller.geometry.ph_quintic import PhQuintic

MAX_BLEND_ANGLE_RAD = math.radians(175.0)  # sharper reversals stop instead of looping round
MAX_SHARE = 0.45  # a blend takes at most this share of each neighbouring piece
BISECTIONS = 30
MIN_CUT_MM = 1e-4


def _point(piece: Piece, s_local: float) -> tuple[complex, complex]:
    """Point and unit tangent at a local arc length of a piece (before chaining, s0 = 0)."""
    u = piece.u_at(np.array([s_local]))
    d = piece.curve.evaluate(u, 1)[:, 0]
    t = complex(d[1, 0], d[1, 1])
    return complex(d[0, 0], d[0, 1]), t / abs(t)


def _blend(a: Piece, b: Piece, cut_mm: float) -> PhQuintic:
    p0, t0 = _point(a, a.length_mm - cut_mm)
    p5, t1 = _point(b, cut_mm)
    chord = abs(p5 - p0)
    return PhQuintic.hermite(p0, p5, t0 * chord, t1 * chord)


def _polyline(a: Piece, b: Piece, cut_mm: float, n: int = 64) -> np.ndarray:
    """The programmed path the blend replaces: the end of a and the start of b (a line needs
    only its two ends)."""
    s_a = np.linspace(a.length_mm - cut_mm, a.length_mm, 2 if a.kind == PieceKind.LINE else n)
    s_b = np.linspace(0.0, cut_mm, 2 if b.kind == PieceKind.LINE else n)
    pa = a.curve.evaluate(a.u_at(s_a), 0)[0]
    pb = b.curve.evaluate(b.u_at(s_b), 0)[0]
    return np.vstack([pa, pb])


def deviation_mm(ph: PhQuintic, poly: np.ndarray, n: int = 65) -> float:
    """Largest distance from the blend to the programmed path it replaces."""
    pts = ph.point(np.linspace(0.0, 1.0, n))
    pts = np.column_stack([pts.real, pts.imag]) if np.iscomplexobj(pts) else pts
    a, b = poly[:-1], poly[1:]
    ab = b - a
    rel = pts[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("pij,ij->pi", rel, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab),
                                                               1e-300), 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return float(np.min(np.linalg.norm(pts[:, None, :] - nearest, axis=2), axis=1).max())


def _fits(a: Piece, b: Piece, cut_mm: float, tol_mm: float) -> tuple[float, PhQuintic] | None:
    ph = _blend(a, b, cut_mm)
    return (cut_mm, ph) if deviation_mm(ph, _polyline(a, b, cut_mm)) <= tol_mm else None


def blend_joint(a: Piece, b: Piece, tolerance_mm: float) -> tuple[Piece, Piece, Piece] | None:
    """(a trimmed, PH blend, b trimmed) with deviation <= tolerance, or None to stop there."""
    if a.kind == PieceKind.PH or b.kind == PieceKind.PH or tolerance_mm <= 0:
        return None
    _, t0 = _point(a, a.length_mm)
    _, t1 = _point(b, 0.0)
    if abs(math.atan2((t1 / t0).imag, (t1 / t0).real)) > MAX_BLEND_ANGLE_RAD:
        return None
    hi = MAX_SHARE * min(a.length_mm, b.length_mm)
    best = _fits(a, b, hi, tolerance_mm)
    lo = 0.0
    for _ in range(BISECTIONS if best is None else 0):
        mid = 0.5 * (lo + hi)
        trial = _fits(a, b, mid, tolerance_mm)
        if trial is None:
            hi = mid
        else:
            best, lo = trial, mid
    if best is None or best[0] < MIN_CUT_MM:
        return None
    cut, ph = best
    u_a = float(a.u_at(np.array([a.length_mm - cut]))[0])
    u_b = float(b.u_at(np.array([cut]))[0])
    a_cut = make_piece(a.kind, a.curve, a.u0, u_a, 0.0, a.feed_mm_s, a.line, a.corner)
    b_cut = make_piece(b.kind, b.curve, u_b, b.u1, 0.0, b.feed_mm_s, b.line, b.corner)
    blend = Piece(PieceKind.PH, ph, 0.0, 1.0, 0.0, ph.length_mm, b.feed_mm_s, b.line)
    return a_cut, blend, b_cut
