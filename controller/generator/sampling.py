"""Interpolation: the planned feed profile turned into one reference point per sample period."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from controller.errors import PlanningError
from controller.generator.feed.profile import FeedProfile
from controller.geometry.arclength import INVERSE_TOL_MM
from controller.geometry.path import Path, PieceKind
from controller.geometry.ph_interpolate import ph_interpolate_many
from controller.geometry.taylor import taylor_interpolate
from controller.numeric import clamp, is_in_sorted, sorted_unique


class Interpolation(StrEnum):
    # PH corners by Newton on the closed-form arc length (eq. 12); NURBS parts by the checked
    # inverse of their arc-length table (arclength_inverse). The second-order Taylor step
    # (eq. 5), even re-anchored on the exact parameter every sample, left single-step errors of
    # 0.5 um next to the NACA leading edge (fast-changing parametric speed), i.e. finite-
    # difference tangential accelerations of 3350 mm/s^2 > Amax: measured, so the NURBS parts
    # are arc-length exact too.
    PH_AND_EXACT_ARC_LENGTH = "ph+exact-arc-length"
    # Plain sequential Taylor (Tsai et al. 2008): its errors accumulate along each NURBS block.
    SEQUENTIAL_TAYLOR = "sequential-taylor"


@dataclass(frozen=True, eq=False, repr=False)
class Samples:
    """Reference points of one run at t = T, 2T, ..., the last one at the run's end point."""

    t_s: np.ndarray
    s_mm: np.ndarray  # planned arc length
    v_mm_s: np.ndarray  # planned feed
    a_mm_s2: np.ndarray  # planned tangential acceleration
    xy_mm: np.ndarray  # (N, 2)
    phi_rad: np.ndarray  # path tangent angle
    line: np.ndarray


MAX_PLANNED_RUN_S = 3600.0  # no window or run plans longer than this (see sample_profile)


def sample_profile(profile: FeedProfile, sample_period_s: float) -> tuple[np.ndarray, ...]:
    """(t, s, v, a) at t = kT for k = 1..K, K = ceil(duration / T); the last is the end."""
    if profile.duration_s > MAX_PLANNED_RUN_S:
        # Last line of defence: a look-ahead window or run is at most a few minutes of motion
        # (long blocks come in parts, a NURBS over 600 s is refused); one planned far longer
        # is a broken plan, and its samples alone would need gigabytes.
        raise PlanningError(f"a planned stretch of {profile.duration_s:.0f} s of motion, "
                            f"longer than any window may take ({MAX_PLANNED_RUN_S:.0f} s): the "
                            "path could not be planned (a fault of the planner: please report "
                            "the program)")
    k_count = max(int(np.ceil(profile.duration_s / sample_period_s - 1e-9)), 1)
    t = np.arange(1, k_count + 1) * sample_period_s
    s, v, a = profile.evaluate(np.minimum(t, profile.duration_s))
    return t, s, v, a


def _by_curve(path: Path, pieces: np.ndarray) -> list[list[int]]:
    """Piece indices grouped by the curve they lie on (a NURBS split by its corner zones)."""
    groups: dict[int, list[int]] = {}
    for i in pieces.tolist():
        groups.setdefault(id(path.pieces[i].curve), []).append(i)
    return list(groups.values())


def _points_on_curve(path: Path, pieces: list[int], idx: np.ndarray,
                     s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, points, tangent angles) of the samples on pieces of one curve: one arc-length
    inversion and one evaluation for all of them."""
    ps = [path.pieces[i] for i in pieces]
    curve = ps[0].curve
    all_rows, count = _rows_by_piece(np.asarray(pieces), idx)
    curve_s0 = curve.s_of_u(np.array([p.u0 for p in ps]))  # each piece's offset in its curve
    length = np.array([p.length_mm for p in ps])
    start = np.array([p.s0_mm for p in ps])
    k = np.repeat(np.arange(len(ps)), count)
    local = clamp(s[all_rows] - start[k], 0.0, length[k])
    u = curve.u_of_s(local + curve_s0[k], INVERSE_TOL_MM)
    lo = np.array([min(p.u0, p.u1) for p in ps])
    hi = np.array([max(p.u0, p.u1) for p in ps])
    u = clamp(u, lo[k], hi[k])
    d = curve.evaluate(u, 1)
    return all_rows, d[0], np.arctan2(d[1, :, 1], d[1, :, 0])


def _rows_by_piece(pieces: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows whose piece (idx) is one of pieces, grouped in the order of pieces and
    ascending within each, and each piece's count: one pass over idx, not one per piece (the
    copies of a repeated NURBS share its curve: a hundred pieces over 30,000 samples)."""
    order = np.argsort(pieces, kind="stable")
    sorted_pieces = pieces[order]
    pos = np.minimum(np.searchsorted(sorted_pieces, idx), len(pieces) - 1)
    on = np.flatnonzero(sorted_pieces[pos] == idx)
    which = order[pos[on]]  # each such row's index into pieces
    return on[np.argsort(which, kind="stable")], np.bincount(which, minlength=len(pieces))


def _points_on_lines(path: Path, pieces: np.ndarray, idx: np.ndarray,
                     s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """_points_on_curve for the samples on LINE pieces (sorted piece indices), all at once: the
    same operations per sample (LineCurve: u = s / length, p0 + u d, the tangent of d), so the
    same numbers, without a call per line of a G1 program."""
    all_pieces = path.pieces
    rows = np.array([(*c.p0, *c.p1, c.length_mm)  # type: ignore[attr-defined]
                     for c in [all_pieces[i].curve for i in pieces.tolist()]],
                    float).reshape(-1, 5)
    k = np.searchsorted(pieces, idx)
    ends, length = rows[:, :4], rows[:, 4]
    d = np.column_stack((ends[:, 2] - ends[:, 0], ends[:, 3] - ends[:, 1]))
    cols = path.columns
    u0, u1 = cols.u0[pieces], cols.u1[pieces]
    start, piece_len = cols.s0_mm[pieces], cols.length_mm[pieces]
    local = clamp(s - start[k], 0.0, piece_len[k])
    u = (local + (u0 * length)[k]) / length[k]
    u = clamp(u, np.minimum(u0, u1)[k], np.maximum(u0, u1)[k])
    xy = np.empty((len(s), 2))
    xy[:, 0] = ends[k, 0] + u * d[k, 0]
    xy[:, 1] = ends[k, 1] + u * d[k, 1]
    tangent = d[k]
    return xy, np.arctan2(tangent[:, 1], tangent[:, 0])


def _sequential_taylor(path: Path, idx: np.ndarray, v: np.ndarray, a: np.ndarray,
                       xy: np.ndarray, sample_period_s: float) -> None:
    """Fill xy for NURBS pieces by running eq. 5 along each NURBS curve from its first sample."""
    done: set[int] = set()
    for i, piece in enumerate(path.pieces):
        if piece.kind != PieceKind.NURBS or id(piece.curve) in done:
            continue
        done.add(id(piece.curve))
        same = [j for j, p in enumerate(path.pieces) if p.curve is piece.curve]
        rows = np.flatnonzero(is_in_sorted(idx, same))
        if rows.size == 0:
            continue
        u0 = piece.u0 if rows[0] == 0 else float(path.pieces[i].u_at(
            np.array([path.pieces[i].s0_mm]))[0])
        u = taylor_interpolate(piece.curve, u0, v[rows], a[rows], sample_period_s)[1:]
        xy[rows] = piece.curve.evaluate(u, 0)[0]


def interpolate(path: Path, profile: FeedProfile, sample_period_s: float,
                method: Interpolation) -> Samples:
    """Reference points for the whole run; the final point is exactly the path's end."""
    t, s, v, a = sample_profile(profile, sample_period_s)
    idx = path.piece_index(s)
    xy = np.empty((s.size, 2))
    phi = np.empty(s.size)
    present = sorted_unique(idx)
    cols = path.columns
    kinds = cols.of_kind(PieceKind.PH)[present]
    ph_pieces = present[kinds]
    if ph_pieces.size:  # every PH corner's samples in one vectorised Newton iteration
        rows = np.flatnonzero(is_in_sorted(idx, ph_pieces))
        which = np.searchsorted(ph_pieces, idx[rows])
        ph = [path.pieces[i] for i in ph_pieces.tolist()]
        s0 = cols.s0_mm[ph_pieces]
        local = s[rows] - s0[which]
        if np.any(cols.u0[ph_pieces] != 0.0):  # a PH piece trimmed by a window's cut
            local = local + np.array([p.curve_s0_mm if p.u0 != 0.0 else 0.0 for p in ph])[which]
        xy[rows], phi[rows] = ph_interpolate_many(
            [p.curve for p in ph], which, local)  # type: ignore[misc]
    others = present[~kinds]
    lines = cols.of_kind(PieceKind.LINE)[others]
    if lines.any():
        rows = np.flatnonzero(is_in_sorted(idx, others[lines]))
        xy[rows], phi[rows] = _points_on_lines(path, others[lines], idx[rows], s[rows])
    for pieces in _by_curve(path, others[~lines]):
        rows, xy_exact, phi_exact = _points_on_curve(path, pieces, idx, s)
        phi[rows] = phi_exact
        if path.pieces[pieces[0]].kind != PieceKind.NURBS or \
                method == Interpolation.PH_AND_EXACT_ARC_LENGTH:
            xy[rows] = xy_exact
    if method == Interpolation.SEQUENTIAL_TAYLOR:
        _sequential_taylor(path, idx, v, a, xy, sample_period_s)
    xy[-1] = path.end_xy
    return Samples(t, s, v, a, xy, phi, cols.line[idx])  # path.line_at(s), gathered
