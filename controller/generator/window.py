"""Look-ahead windows: where to cut a window planned to rest so the next one continues it."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig
from controller.generator.replan import Continuation, RunPlan
from controller.geometry.path import Piece, chain, make_piece
from controller.servo.band import band_servos, band_states_after
from controller.servo.prediction import axis_servos, state_after
from controller.servo.true_distance import NEAR_SAMPLES

# The end of a window is planned again with the next blocks: this share of it, and at least
# MIN_OVERLAP_MM (several braking distances at Vmax: what the stop at the window's end and the
# dynamics rounds' look-back can reach). A quarter cost a third more planning on long runs.
OVERLAP_SHARE = 0.05
MIN_OVERLAP_MM = 10.0
# ... but never more than the path of the window's last MIN_OVERLAP_S of motion (braking from
# Vmax takes 36 ms, the rounds look back 30 ms): at F1.27 the 10 mm were 470 s of samples,
# planned again by every window of 30 s (a tiny circle, then 10 mm at F1.27: 245 MB of RSS,
# and 200 mm took 42 s of CPU). Where the last 2 s cover 10 mm (5 mm/s), nothing changes.
MIN_OVERLAP_S = 2.0
MIN_PIECE_MM = 1e-6


def _cruise_samples(run: RunPlan) -> np.ndarray:
    """Samples inside a cruise (zero acceleration before, at and after them), on any piece: in
    a run of short G1 moves the only cruises are through the PH blends, where the curvature
    holds the feed (a cut there is a trimmed PH piece, sampling.py)."""
    s = run.samples
    a, v = s.a_mm_s2, s.v_mm_s
    flat = np.zeros(len(a), bool)
    flat[1:-1] = (a[:-2] == 0.0) & (a[1:-1] == 0.0) & (a[2:] == 0.0) & (v[1:-1] > 0.0) \
        & (v[:-2] == v[1:-1]) & (v[2:] == v[1:-1])
    return flat


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
    last = max(len(s.s_mm) - 1 - int(round(MIN_OVERLAP_S / config.sample_period_s)), 0)
    overlap = min(MIN_OVERLAP_MM, path.length_mm - float(s.s_mm[last]))
    limit = path.length_mm - max(overlap, OVERLAP_SHARE * path.length_mm)
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
    before = s.xy_mm[:k + 1] if cont is None or cont.history_xy is None else \
        np.vstack([cont.history_xy, s.xy_mm[:k + 1]])
    band = band_servos(config)
    states = () if len(band) == 1 else band_states_after(
        s.xy_mm[:k + 1], run.start_xy_mm, band, config.sample_period_s,
        None if cont is None else cont.band)
    return k, Continuation(tail, tolerance_mm, float(s.v_mm_s[k]), s.xy_mm[k].copy(), state,
                           end_mm, before[-(NEAR_SAMPLES + 1):].copy(), states)
