"""The feed-limit grid: (s, kappa) along a path, each piece sampled in its own parameter."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from controller.geometry.curves import Curve
from controller.geometry.path import Path, Piece, PieceKind
from controller.numeric import sorted_unique

# Feed-limit samples per run, their spacing clamped: at most 35 um, under the 58 um a sample
# period covers at full feed. Measured over 17 programs, 35 um planned 0.05 % less motion time
# than 20 um (and fewer dynamics rounds), with half the samples on the long ones.
GRID_POINTS = 5000
MIN_SPACING_MM = 0.002
MAX_SPACING_MM = 0.035


# Keyed by the curve itself, not id(curve): an id is only unique among live objects, and a
# blend freed between dynamics rounds would hand its id (and its samples) to the next one.
PieceSamples = dict[tuple[Curve, float, float, int], tuple[np.ndarray, np.ndarray]]


def _speed_and_kappa(curve: Curve, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows = getattr(curve, "evaluate_rows", None)  # a NURBS: x and y rows contiguous, the same
    d = rows(u, 2) if rows is not None else curve.evaluate(u, 2).transpose(0, 2, 1)
    (dx, dy), (ddx, ddy) = d[1], d[2]
    speed2 = dx * dx + dy * dy
    speed = np.sqrt(speed2)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.abs(dx * ddy - dy * ddx) / (speed2 * speed)
    return speed, np.where(np.isfinite(kappa), kappa, 0.0)  # |C'| = 0: nan or +inf


def _trapezoid_s(u: np.ndarray, speed: np.ndarray, length_mm: float) -> np.ndarray:
    """Arc length at u by the trapezoid rule on |C'|, rescaled to length_mm."""
    s = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u))))
    if s[-1] > 0:
        s *= length_mm / s[-1]
    return s


def _piece_samples(p: Piece, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(local s, kappa) at n parameters of a piece; s by the trapezoid rule on |C'| rescaled to
    the exact piece length (planning needs positions to ~1e-6 mm, not the table's 1e-12).
    A NURBS piece that n even parameters do not resolve is sampled by knot span instead
    (_knot_span_samples), with as many samples as its length needs."""
    u = np.linspace(p.u0, p.u1, n)
    speed, kappa = _speed_and_kappa(p.curve, u)
    s = _trapezoid_s(u, speed, p.length_mm)
    inner = _inner_knots(p)
    if inner is None:
        return s, kappa
    peak = _knot_kappa(p.curve, inner)
    if not _resolved(p, s, kappa, peak, n):
        return _knot_span_samples(p, inner, peak, p.length_mm / (n - 1))
    return s, kappa


# Uniform parameters resolve a NURBS piece when no two samples are further apart than this
# many times their mean spacing (the programs of nc_programs/ and the benchmarks: at most 4.3)
# and no knot's curvature, from either side, exceeds the samples' largest by this factor
# (there: at most 0.95). A quadratic with knot spans 1 and 9999 put one sample on its first
# 5 mm, and its 22 degree turn within 0.5 um of a knot between samples: passed at full feed,
# the tool was 34.6 um off the path.
SPARSE_GAP = 8.0
KNOT_KAPPA = 1.5


def _inner_knots(p: Piece) -> np.ndarray | None:
    knots = getattr(p.curve, "knots", None)
    if knots is None or p.kind != PieceKind.NURBS or not p.u1 > p.u0 or p.length_mm <= 0.0:
        return None
    return sorted_unique(knots[(knots > p.u0) & (knots < p.u1)])


def _knot_kappa(curve: Curve, knots: np.ndarray) -> np.ndarray:
    """Curvature at each knot, the larger of its two sides (it jumps where C'' does)."""
    if not knots.size:
        return np.zeros(0)
    right = _speed_and_kappa(curve, knots)[1]
    left = _speed_and_kappa(curve, np.nextafter(knots, -np.inf))[1]
    return np.maximum(left, right)


def _resolved(p: Piece, s: np.ndarray, kappa: np.ndarray, peak: np.ndarray, n: int) -> bool:
    """Whether n even parameters resolve the piece, peak its knots' curvature."""
    if float(np.diff(s).max()) > SPARSE_GAP * p.length_mm / (n - 1):
        return False
    return not (peak.size and float(peak.max()) > KNOT_KAPPA * float(kappa.max()))


def _knot_span_samples(p: Piece, inner: np.ndarray, peak: np.ndarray,
                       spacing_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(local s, kappa) of a NURBS piece sampled span by span: each knot span gets even
    parameters at about spacing_mm (at least 8 intervals), its arc length exact from the curve's
    table, and each knot the larger curvature of its two sides (peak, _knot_kappa's)."""
    bounds = np.concatenate(([p.u0], inner, [p.u1]))
    s_bounds = p.curve.s_of_u(bounds)
    s_bounds = s_bounds - s_bounds[0]
    span_mm = np.diff(s_bounds)
    counts = np.maximum(np.ceil(span_mm / spacing_mm).astype(int), 8)
    u_parts, s_parts, k_parts = [], [], []
    for i, m in enumerate(counts.tolist()):
        u = np.linspace(bounds[i], bounds[i + 1], m + 1)
        speed, kappa = _speed_and_kappa(p.curve, u)
        u_parts.append(u[:-1])
        s_parts.append(s_bounds[i] + _trapezoid_s(u, speed, float(span_mm[i]))[:-1])
        k_parts.append(kappa[:-1])
    u = np.concatenate((*u_parts, bounds[-1:]))
    s = np.concatenate((*s_parts, [float(s_bounds[-1])]))
    kappa = np.concatenate((*k_parts, _speed_and_kappa(p.curve, bounds[-1:])[1]))
    at_knot = np.searchsorted(u, inner)
    kappa[at_knot] = np.maximum(kappa[at_knot], peak)
    s *= p.length_mm / s[-1] if s[-1] > 0 else 1.0
    return s, kappa


def _batch_rows(pieces: tuple[Piece, ...], index: list[int], counts: list[int]
                ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray | None]]:
    """_piece_samples of the pieces index (all LINE or all PH), grouped by sample count:
    (indices, s rows, kappa rows or None where it is 0), the same operations on arrays of pieces
    with the same count, so the same numbers (tests/generator/test_plan_caches.py compares them
    bit for bit), without numpy's cost per call on every line and blend of a G1 program. Not
    cached: made again, they cost less than a look-up of their keys (a path whose pieces did not
    change has its whole grid cached by plan_path_feed)."""
    by_count: dict[int, list[int]] = {}
    for i in index:
        by_count.setdefault(counts[i], []).append(i)
    for n, group in by_count.items():
        ps = [pieces[i] for i in group]
        u0, u1 = np.array([p.u0 for p in ps]), np.array([p.u1 for p in ps])
        if np.any(u1 == u0):  # linspace treats a zero step apart
            for i, p in zip(group, ps, strict=True):
                row_s, row_k = _piece_samples(p, n)
                yield np.array([i]), row_s[None, :], row_k[None, :]
            continue
        u = np.linspace(u0, u1, n, axis=1)
        speed, kappa = _line_speed(ps, u) if ps[0].kind == PieceKind.LINE else _ph_speed(ps, u)
        yield np.array(group), _trapezoid_rows(ps, u, speed), kappa


def _line_speed(ps: list[Piece], u: np.ndarray) -> tuple[np.ndarray, None]:
    """|C'| of lines at parameters u (one row per line; constant), curvature 0."""
    dx = np.array([p.curve.p1[0] - p.curve.p0[0] for p in ps])  # type: ignore[attr-defined]
    dy = np.array([p.curve.p1[1] - p.curve.p0[1] for p in ps])  # type: ignore[attr-defined]
    return np.broadcast_to(np.sqrt(dx * dx + dy * dy)[:, None], u.shape), None


def _ph_speed(ps: list[Piece], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|C'| and curvature of PH quintics at parameters x (one row per quintic):
    PhQuintic.evaluate's operations (w, w^2, 2 w w'), then _speed_and_kappa's."""
    w0, w1, w2 = (np.array([getattr(p.curve, k) for p in ps])[:, None]
                  for k in ("w0", "w1", "w2"))
    w = w0 * (1 - x) ** 2 + 2 * w1 * (1 - x) * x + w2 * x * x
    d1 = w ** 2
    d2 = 2 * w * (2 * ((w1 - w0) * (1 - x) + (w2 - w1) * x))
    dx, dy, ddx, ddy = d1.real, d1.imag, d2.real, d2.imag
    speed2 = dx * dx + dy * dy
    speed = np.sqrt(speed2)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.abs(dx * ddy - dy * ddx) / (speed2 * speed)
    return speed, np.where(np.isfinite(kappa), kappa, 0.0)


def _trapezoid_rows(ps: list[Piece], u: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """_trapezoid_s on each row: the trapezoids of |C'|, rescaled to its piece's length."""
    s = np.zeros(u.shape)
    np.cumsum(0.5 * (speed[:, 1:] + speed[:, :-1]) * np.diff(u, axis=1), axis=1, out=s[:, 1:])
    length = np.array([p.length_mm for p in ps])
    last = s[:, -1].copy()
    scale = length / np.where(last > 0, last, 1.0)
    s[last > 0] *= scale[last > 0, None]
    return s


def grid_step_mm(path: Path) -> float:
    """Target spacing of the feed-limit grid (each piece's own step is at most this)."""
    # np.clip's numbers in Python floats (np.clip on a scalar costs some 10 us a call)
    return min(max(path.length_mm / GRID_POINTS, MIN_SPACING_MM), MAX_SPACING_MM)


def limit_samples(path: Path, cache: PieceSamples | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(s, kappa) on a fine grid, each piece sampled in its own parameter (no inversion needed).

    At a joint both sides are sampled and the larger curvature is kept (curvature may jump).
    Lines and PH blends are sampled in batches (_batch_rows), NURBS parts and arcs one by one
    through the cache (a dynamics round that widens a corner zone keeps the others' samples)."""
    spacing = grid_step_mm(path)
    cache = {} if cache is None else cache
    pieces, cols = path.pieces, path.columns
    # max(ceil(length / spacing), 8) + 1 per piece (the same numbers in floats: exact)
    counts = (np.maximum(np.ceil(cols.length_mm / spacing), 8.0) + 1.0).astype(np.intp).tolist()
    is_line, is_ph = cols.of_kind(PieceKind.LINE), cols.of_kind(PieceKind.PH)
    rows = {}
    for i in np.flatnonzero(~(is_line | is_ph)).tolist():
        key = (pieces[i].curve, pieces[i].u0, pieces[i].u1, counts[i])
        if key not in cache:
            cache[key] = _piece_samples(pieces[i], counts[i])
        rows[i] = cache[key]
        counts[i] = len(rows[i][0])  # a NURBS piece sampled by knot span has its own count
    # Each piece's samples moved to where it starts on the path, all at once (p.s0_mm + s).
    ends = np.cumsum(counts)
    start = ends - counts
    local, kappa = np.empty(int(ends[-1])), np.zeros(int(ends[-1]))
    for kind in (is_line, is_ph):
        for group, s_rows, k_rows in _batch_rows(pieces, np.flatnonzero(kind).tolist(), counts):
            at = start[group][:, None] + np.arange(s_rows.shape[1])
            local[at] = s_rows
            if k_rows is not None:
                kappa[at] = k_rows
    for i, row in rows.items():
        local[start[i]:ends[i]], kappa[start[i]:ends[i]] = row
    s = np.repeat(cols.s0_mm, counts) + local
    # The pieces follow each other: each one's first sample is the previous one's last point.
    # Keep the larger curvature there, drop the duplicate, then anything not strictly ahead.
    first = ends[:-1]
    kappa[first - 1] = np.maximum(kappa[first - 1], kappa[first])
    s, kappa = np.delete(s, first), np.delete(kappa, first)
    if np.all(np.diff(s) > 1e-12):
        return s, kappa
    order = np.lexsort((-kappa, s))  # a degenerate piece: by s, larger curvature first
    s, kappa = s[order], kappa[order]
    keep = np.r_[True, np.diff(s) > 1e-12]
    return s[keep], kappa[keep]
