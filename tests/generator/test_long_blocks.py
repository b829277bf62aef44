"""Long blocks in bounded parts: an arc of many turns, a line at 1 mm/min, a long dwell or Z move
are planned and sent a bounded piece at a time, along the same path."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of, motion

from controller.blocks import ArcBlock, LineBlock, PathControl, Source
from controller.generator.long_blocks import (
    CHUNK_SAMPLES,
    MAX_PART_SWEEP_RAD,
    NURBS_PART_NOMINAL_S,
    PART_NOMINAL_S,
    contour_parts,
    nurbs_parts,
)
from controller.generator.plan import WINDOW_NOMINAL_S, plan_program

SRC = Source("t.nc", 3, 3)
VMAX = XY_TABLE.interpolator.max_feed_mm_s
REPO = Path(__file__).resolve().parents[2]


def _arc(start: tuple, center: tuple, clockwise: bool, turns: int, feed: float) -> ArcBlock:
    return ArcBlock(start, start, center, clockwise, turns, feed, PathControl(), SRC)


def test_a_short_block_is_left_as_it_is() -> None:
    line = LineBlock((0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 10.0, False, PathControl(), SRC)
    assert list(contour_parts(line, VMAX)) == [line] and next(contour_parts(line, VMAX)) is line


@settings(max_examples=200, deadline=None)
@given(st.floats(-100, 100), st.floats(-100, 100), st.floats(-100, 100), st.floats(-100, 100),
       st.floats(1 / 60, 50))
def test_line_parts_follow_the_line_end_to_end(x0: float, y0: float, x1: float, y1: float,
                                               feed: float) -> None:
    line = LineBlock((x0, y0, 1.0), (x1, y1, 1.0), feed, False, PathControl(), SRC)
    parts = list(contour_parts(line, VMAX))
    assert parts[0].start == line.start and parts[-1].end == line.end
    assert all(a.end == b.start for a, b in zip(parts, parts[1:], strict=False))
    nominal = [p.length_mm / min(feed, VMAX) for p in parts]
    assert len(parts) == 1 or max(nominal) <= PART_NOMINAL_S * (1 + 1e-9)
    assert math.isclose(sum(p.length_mm for p in parts), line.length_mm, rel_tol=1e-9,
                        abs_tol=1e-9)
    assert all(p.source == SRC and p.feed_mm_s == feed for p in parts)


@settings(max_examples=80, deadline=None)
@given(st.floats(0.01, 50), st.floats(0, 2 * math.pi), st.booleans(), st.integers(0, 120),
       st.floats(1 / 60, 50))
def test_arc_parts_turn_as_the_arc_does(r: float, a0: float, clockwise: bool, turns: int,
                                        feed: float) -> None:
    center = (5.0, -3.0)
    start = (center[0] + r * math.cos(a0), center[1] + r * math.sin(a0), 0.0)
    arc = _arc(start, center, clockwise, turns, feed)
    parts = list(contour_parts(arc, VMAX))
    assert parts[0].start == arc.start and parts[-1].end == arc.end
    assert all(a.end == b.start for a, b in zip(parts, parts[1:], strict=False))
    assert math.isclose(sum(p.sweep_rad for p in parts), arc.sweep_rad, rel_tol=1e-9)
    if len(parts) > 1:
        assert all(p.turns == 0 and p.clockwise == clockwise and p.center == center
                   for p in parts)
        assert max(abs(p.sweep_rad) for p in parts) <= MAX_PART_SWEEP_RAD * (1 + 1e-9)
        assert max(p.length_mm for p in parts) / min(feed, VMAX) <= PART_NOMINAL_S * 1.001
        assert all(math.isclose(p.radius_mm, r, rel_tol=1e-9) for p in parts)


def _chunk_lengths(tmp_path: Path, text: str, config=XY_TABLE) -> list[int]:
    path = tmp_path / "long.nc"
    path.write_text(text)
    from controller.interpreter.program import read_program
    return [len(step.chunk) for step in plan_program(read_program(str(path), config), config)]


def test_an_arc_of_100_turns_is_planned_in_bounded_windows(tmp_path: Path) -> None:
    lengths = _chunk_lengths(tmp_path, "G21 G90 F1000\nG2 X0 Y0 I0 J10 P100\nM2\n")
    period = XY_TABLE.sample_period_s
    assert len(lengths) > 5
    assert max(lengths) * period < 2 * (WINDOW_NOMINAL_S + PART_NOMINAL_S)
    nominal_s = 100 * 2 * math.pi * 10 / (1000 / 60)  # P100: 100 turns in all
    assert sum(lengths) * period > nominal_s  # the whole arc, at most at its feed


def test_a_long_dwell_and_a_slow_z_move_come_in_chunks(tmp_path: Path) -> None:
    lengths = _chunk_lengths(tmp_path, "G21 G90\nG4 P100\nG1 Z-10 F6\nM2\n", XYZ_MILL)
    assert max(lengths) <= CHUNK_SAMPLES
    assert sum(lengths) * XYZ_MILL.sample_period_s > 100 + 100  # the dwell, then 10 mm at 0.1


def test_the_chunks_of_a_slow_z_move_join_without_a_step(tmp_path: Path) -> None:
    path = tmp_path / "z.nc"
    path.write_text("G21 G90\nG1 Z-5 F6\nM2\n")
    from controller.interpreter.program import read_program
    steps = list(plan_program(read_program(str(path), XYZ_MILL), XYZ_MILL))
    z = np.concatenate([s.chunk.pos_mm[:, 2] for s in steps])
    t = np.concatenate([s.chunk.t0_s + np.arange(len(s.chunk)) * XYZ_MILL.sample_period_s
                        for s in steps])
    assert len(steps) > 2 and z[-1] == -5.0
    assert np.allclose(np.diff(t), XYZ_MILL.sample_period_s)  # one clock across the chunks
    assert np.max(np.abs(np.diff(z))) <= 0.1 * XYZ_MILL.sample_period_s * 1.0001


def test_blocks_of_a_long_program_keep_their_line(tmp_path: Path) -> None:
    blocks = motion(blocks_of(tmp_path, "G21 G90 F60\nG1 X20\nM2\n"))
    parts = list(contour_parts(blocks[0], VMAX))  # 20 s at 1 mm/s: two parts
    assert len(parts) == 2 and {p.source.first_line for p in parts} == {2}


def test_a_jump_of_the_reference_is_a_planning_error() -> None:
    import pytest

    from controller.errors import PlanningError
    from controller.generator.plan import check_steps
    from controller.refpoints import RefChunk

    step_mm = XY_TABLE.interpolator.max_feed_mm_s * XY_TABLE.sample_period_s
    pos = np.column_stack((np.arange(5) * step_mm, np.zeros(5)))
    line = np.full(5, 7, np.int32)
    check_steps(RefChunk(0.001, pos, np.zeros(5), line), None, XY_TABLE)  # at full feed: fine
    jumped = pos.copy()
    jumped[3:, 0] += 10.0
    with pytest.raises(PlanningError, match=r"line 7: the planned reference jumps 10\.0"):
        check_steps(RefChunk(0.001, jumped, np.zeros(5), line), None, XY_TABLE)
    with pytest.raises(PlanningError):  # from the last point of the chunk before, too
        check_steps(RefChunk(0.001, pos, np.zeros(5), line), np.array([-10.0, 0.0]), XY_TABLE)


def _slow_airfoil(tmp_path: Path, feed_mm_min: float) -> list:
    text = (REPO / "nc_programs" / "naca2415.nc").read_text()
    return blocks_of(tmp_path, text.replace("F3500", f"F{feed_mm_min:g}"))


def test_a_slow_nurbs_is_split_at_smooth_knots_into_parts_of_the_same_curve(
        tmp_path: Path) -> None:
    """The airfoil at F6.2 (598 s) was one window of 598 s of samples: 260 MB."""
    from controller.blocks import NurbsBlock
    from controller.geometry.nurbs import Nurbs
    (block,) = [b for b in motion(_slow_airfoil(tmp_path, 6.2)) if isinstance(b, NurbsBlock)]
    kappa_th = XY_TABLE.interpolator.kappa_threshold_per_mm
    parts = nurbs_parts(block, VMAX, kappa_th)
    assert len(parts) >= 10
    whole = Nurbs.from_block(block)
    curves = [Nurbs.from_block(p) for p in parts]
    assert sum(c.length_mm for c in curves) == pytest.approx(whole.length_mm, rel=1e-9)
    feed = block.feed_mm_s
    for a, b in zip(curves, curves[1:], strict=False):
        end, start = a.evaluate([a.u_end], 1), b.evaluate([b.u_start], 1)
        assert np.allclose(end[0], start[0], atol=1e-9)  # the same point ...
        ta, tb = end[1, 0] / np.linalg.norm(end[1, 0]), start[1, 0] / np.linalg.norm(start[1, 0])
        assert float(ta @ tb) > 1.0 - 1e-9  # ... and tangent: nothing stops there
        assert max(a.curvature([a.u_end])[0], b.curvature([b.u_start])[0]) < 0.5 * kappa_th
    assert max(c.length_mm / feed for c in curves) <= NURBS_PART_NOMINAL_S * 1.5
    # Points of each part lie on the whole curve (same parameters: the split keeps them).
    for c in curves:
        u = np.linspace(c.u_start, c.u_end, 7)
        assert np.allclose(c.evaluate(u, 0)[0], whole.evaluate(u, 0)[0], atol=1e-9)
    fast = dataclasses.replace(block, feed_mm_s=VMAX)  # 1 s at full feed: left whole
    (whole_block,) = nurbs_parts(fast, VMAX, kappa_th)
    assert whole_block is fast


def test_a_slow_nurbs_is_planned_in_bounded_windows(tmp_path: Path) -> None:
    steps = list(plan_program(_slow_airfoil(tmp_path, 6.2), XY_TABLE))
    longest_s = max(len(s.chunk) for s in steps) * XY_TABLE.sample_period_s
    assert longest_s < NURBS_PART_NOMINAL_S + WINDOW_NOMINAL_S + 5.0  # was 598 s
    total_s = sum(len(s.chunk) for s in steps) * XY_TABLE.sample_period_s
    assert total_s == pytest.approx(597.8, rel=1e-3)


def test_an_arc_of_a_million_turns_starts_at_once_in_bounded_memory(tmp_path: Path) -> None:
    """Three hours of a 0.2 mm circle: its two million half-turn parts were a list made
    before the first sample (gigabytes); now the first seconds plan in a few megabytes."""
    import itertools
    import tracemalloc

    from controller.interpreter.program import read_program

    path = tmp_path / "turns.nc"
    path.write_text("G21 G90 F3000\nG1 X0.2\nG2 X0.2 Y0 I-0.1 J0 P1000000\nM2\n")
    tracemalloc.start()
    try:
        steps = list(itertools.islice(plan_program(read_program(str(path), XY_TABLE),
                                                   XY_TABLE), 12))
        peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
    finally:
        tracemalloc.stop()
    assert sum(len(s.chunk) for s in steps) > 300
    assert peak_mb < 200, peak_mb


@pytest.mark.parametrize("text, word", [
    ("G21 G90\nG4 P99999999999999999999\nM2\n", "2:4: error: G4 dwell of 1e+20 s"),
    ("G21 G90\nG2 X0 Y0 I-0.4 J-15.18 P1000000 F1.5\nM2\n", "2:24: error: this move of"),
    ("G21 G90 F1\nG1 X149\nG1 X-149\nG1 X149 Y0.001\nM2\n", None),  # 5 h of moves: fine
])
def test_check_refuses_a_block_of_more_than_a_day(tmp_path: Path, text: str,
                                                   word: str | None) -> None:
    """The dwell passed `check`, then the generator grew to its memory limit."""
    from controller.errors import NcError
    from controller.interpreter.program import read_program

    path = tmp_path / "long.nc"
    path.write_text(text)
    if word is None:
        list(read_program(str(path), XY_TABLE))
        return
    with pytest.raises(NcError) as err:
        list(read_program(str(path), XY_TABLE))
    assert word in err.value.format()
