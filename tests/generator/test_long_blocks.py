"""Long blocks in bounded parts: an arc of many turns, a line at 1 mm/min, a long dwell or Z move
are planned and sent a bounded piece at a time, along the same path."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of, motion

from controller.blocks import ArcBlock, LineBlock, PathControl, Source
from controller.generator.long_blocks import (
    CHUNK_SAMPLES,
    MAX_PART_SWEEP_RAD,
    PART_NOMINAL_S,
    contour_parts,
)
from controller.generator.plan import WINDOW_NOMINAL_S, plan_program

SRC = Source("t.nc", 3, 3)
VMAX = XY_TABLE.interpolator.max_feed_mm_s


def _arc(start: tuple, center: tuple, clockwise: bool, turns: int, feed: float) -> ArcBlock:
    return ArcBlock(start, start, center, clockwise, turns, feed, PathControl(), SRC)


def test_a_short_block_is_left_as_it_is() -> None:
    line = LineBlock((0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 10.0, False, PathControl(), SRC)
    assert contour_parts(line, VMAX) == [line] and contour_parts(line, VMAX)[0] is line


@settings(max_examples=200, deadline=None)
@given(st.floats(-100, 100), st.floats(-100, 100), st.floats(-100, 100), st.floats(-100, 100),
       st.floats(1 / 60, 50))
def test_line_parts_follow_the_line_end_to_end(x0: float, y0: float, x1: float, y1: float,
                                               feed: float) -> None:
    line = LineBlock((x0, y0, 1.0), (x1, y1, 1.0), feed, False, PathControl(), SRC)
    parts = contour_parts(line, VMAX)
    assert parts[0].start == line.start and parts[-1].end == line.end
    assert all(a.end == b.start for a, b in zip(parts, parts[1:], strict=False))
    nominal = [p.length_mm / min(feed, VMAX) for p in parts]
    assert len(parts) == 1 or max(nominal) <= PART_NOMINAL_S * (1 + 1e-9)
    assert math.isclose(sum(p.length_mm for p in parts), line.length_mm, rel_tol=1e-9,
                        abs_tol=1e-9)
    assert all(p.source == SRC and p.feed_mm_s == feed for p in parts)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.01, 50), st.floats(0, 2 * math.pi), st.booleans(), st.integers(0, 300),
       st.floats(1 / 60, 50))
def test_arc_parts_turn_as_the_arc_does(r: float, a0: float, clockwise: bool, turns: int,
                                        feed: float) -> None:
    center = (5.0, -3.0)
    start = (center[0] + r * math.cos(a0), center[1] + r * math.sin(a0), 0.0)
    arc = _arc(start, center, clockwise, turns, feed)
    parts = contour_parts(arc, VMAX)
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
    parts = contour_parts(blocks[0], VMAX)  # 20 s at 1 mm/s: two parts
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
