"""The generator's per-run caches: a curve's entry can never be found by another curve."""

from __future__ import annotations

from pathlib import Path as FsPath

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import load_config
from controller.generator.feed import grid
from controller.generator.feed.grid import limit_samples
from controller.generator.feed.planner import clear_memo
from controller.geometry.curves import ArcCurve, LineCurve
from controller.geometry.path import Path, PieceKind, chain, make_piece
from controller.geometry.ph_quintic import PhQuintic
from controller.interpreter.program import read_program
from controller.runtime.simulation import simulate

CFG = load_config()

# Found by test_generator_fuzz.py: G1 corners blended within G64 P0.01, arcs and a rapid,
# seven dynamics rounds. Each round rebuilds the blends; a freed blend's id, recycled by a new
# one, used to return the old blend's curvature samples, and the plan varied from run to run
# (tangential acceleration up to 3700 mm/s^2 against Amax 2450).
BLENDED = """G17 G21 G90
F1542
G64 P0.01
G1 X3.316 Y31.644
G3 X6.343 Y-18.516 I1.5135 J-25.0800
G0 X31.314 Y54.269
G1 X-10.058 Y49.952
G1 X-37.691 Y59.105
G2 X-45.493 Y-20.077 I-3.9010 J-39.5910
G3 X0.926 Y49.222 I23.2095 J34.6495
M2
"""


def _path(kind: PieceKind, curve: LineCurve | ArcCurve) -> Path:
    return Path(chain([make_piece(kind, curve, 0.0, 1.0, 0.0, 50.0, 1)]))


def test_the_sample_cache_holds_its_curves_so_their_ids_cannot_be_recycled() -> None:
    # (Lines are not cached at all: made again, they cost less than a look-up.)
    other = _path(PieceKind.ARC, ArcCurve((0.0, 2.0), 2.0, -np.pi / 2, np.pi / 3))
    fresh_s, fresh_kappa = limit_samples(other)
    cache: dict = {}
    limit_samples(_path(PieceKind.ARC, ArcCurve((0.0, 5.0), 5.0, -np.pi / 2, np.pi / 2)), cache)
    # The arc's path is gone; its curve lives on as the cache's key, so no new curve can take
    # its id, and the other arc gets samples of its own.
    ((arc_curve, *_),) = cache.keys()
    assert isinstance(arc_curve, ArcCurve)
    s, kappa = limit_samples(other, cache)
    np.testing.assert_array_equal(s, fresh_s)
    np.testing.assert_array_equal(kappa, fresh_kappa)
    assert len(cache) == 2


def test_repeated_plans_of_a_blended_program_are_identical_and_within_limits(
        tmp_path: FsPath) -> None:
    prog = tmp_path / "blended.nc"
    prog.write_text(BLENDED, encoding="utf-8")
    refs = []
    for _ in range(3):
        clear_memo()
        traj = simulate(read_program(str(prog), CFG), CFG, "ph-lookahead")
        refs.append(traj.ref_mm)
        v = np.linalg.norm(np.diff(traj.ref_mm, axis=0), axis=1) / CFG.sample_period_s
        a_t = np.abs(np.diff(v)) / CFG.sample_period_s
        assert a_t.max() <= CFG.interpolator.max_accel_mm_s2 * (1 + 1e-6)
    for r in refs[1:]:
        np.testing.assert_array_equal(r, refs[0])


@settings(max_examples=40, deadline=None)
@given(data=st.lists(st.tuples(st.complex_numbers(max_magnitude=3.0, allow_nan=False,
                                                  allow_infinity=False),
                               st.floats(0.0, 0.45), st.floats(0.55, 1.0)),
                     min_size=1, max_size=12),
       n=st.integers(2, 40))
def test_pieces_sampled_together_are_sampled_as_one_by_one(
        data: list[tuple[complex, float, float]], n: int) -> None:
    """PH blends (a G1 program has one at every joint) and lines are sampled a batch at a
    time; the numbers are those of _piece_samples, bit for bit, cut pieces included."""
    pieces: list = []
    cache: dict = {}
    for k, (turn, u0, u1) in enumerate(data):
        d1 = complex(1.0, 0.0) + turn
        if abs(d1) < 1e-3:
            continue
        ph = PhQuintic.hermite(0j, complex(1.0, 0.2 * k), 1 + 0j, d1)
        pieces.append(make_piece(PieceKind.PH, ph, u0, u1, 0.0, 50.0, 1))
        pieces.append(make_piece(PieceKind.LINE, LineCurve((0.0, k), (1.0 + u1, k)), u0, u1,
                                 0.0, 50.0, 1))
    for kind in (PieceKind.PH, PieceKind.LINE):
        index = [i for i, p in enumerate(pieces) if p.kind == kind]
        for group, rows, kappas in grid._batch_rows(tuple(pieces), index, [n] * len(pieces)):
            for j, i in enumerate(group.tolist()):
                kappa = np.zeros(n) if kappas is None else kappas[j]
                cache[(pieces[i].curve, pieces[i].u0, pieces[i].u1, n)] = (rows[j], kappa)
    for p in pieces:
        s, kappa = cache[(p.curve, p.u0, p.u1, n)]
        one_s, one_kappa = grid._piece_samples(p, n)
        np.testing.assert_array_equal(s, one_s)
        np.testing.assert_array_equal(kappa, one_kappa)
