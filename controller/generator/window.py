"""Look-ahead windows: where to cut a window planned to rest so the next one continues it."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig
from controller.generator.dynamics.prediction import axis_servos, state_after
from controller.generator.loop import Continuation, RunPlan
from controller.geometry.path import Piece, PieceKind, chain, make_piece

OVERLAP_SHARE = 0.25  # the last quarter of a window is planned again with the next blocks
MIN_OVERLAP_MM = 10.0  # ... and at least this much (several braking distances at Vmax)
MIN_PIECE_MM = 1e-6


def _cruise_samples(run: RunPlan) -> np.ndarray:
    """Samples inside a cruise (zero acceleration before, at and after them), not on a PH."""
    s = run.samples
    a, v = s.a_mm_s2, s.v_mm_s
    flat = np.zeros(len(a), bool)
    flat[1:-1] = (a[:-2] == 0.0) & (a[1:-1] == 0.0) & (a[2:] == 0.0) & (v[1:-1] > 0.0) \
        & (v[:-2] == v[1:-1]) & (v[2:] == v[1:-1])
    path = run.geometry.path
    kinds = np.array([p.kind != PieceKind.PH for p in path.pieces])
    return flat & kinds[path.piece_index(s.s_mm)]


def _tail(pieces: tuple[Piece, ...], index: int, s_cut_mm: float) -> tuple[Piece, ...]:
    """The path from s_cut on: the cut piece trimmed, then every later piece, re-chained."""
    p = pieces[index]
    u = float(p.u_at(np.array([s_cut_mm]))[0])
    rest = list(pieces[index + 1:])
    if p.s0_mm + p.length_mm - s_cut_mm > MIN_PIECE_MM:
        rest.insert(0, make_piece(p.kind, p.curve, u, p.u1, 0.0, p.feed_mm_s, p.line, p.corner))
    return chain(rest)


def continuation_cut(run: RunPlan, tolerance_mm: float | None, end_mm: tuple[float, float, float],
                     config: MachineConfig,
                     cont: Continuation | None) -> tuple[int, Continuation] | None:
    """The last cruise sample before the overlap, and what the next window needs from it."""
    s = run.samples
    path = run.geometry.path
    if path.stops_at_mm:
        return None  # a stop inside the window: keep it whole (a stop is a natural cut)
    limit = path.length_mm - max(MIN_OVERLAP_MM, OVERLAP_SHARE * path.length_mm)
    ok = np.flatnonzero(_cruise_samples(run) & (s.s_mm <= limit))
    if ok.size == 0:
        return None
    k = int(ok[-1])
    servos = axis_servos(config)
    state = state_after(s.xy_mm[:k + 1], run.start_xy_mm, servos, config.sample_period_s,
                        None if cont is None else cont.servo)
    index = int(path.piece_index(np.array([s.s_mm[k]]))[0])
    tail = _tail(path.pieces, index, float(s.s_mm[k]))
    if not tail:
        return None
    return k, Continuation(tail, tolerance_mm, float(s.v_mm_s[k]), s.xy_mm[k].copy(), state,
                           end_mm)
