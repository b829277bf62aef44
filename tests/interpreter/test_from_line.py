"""Run from line N: read_program(from_line=N) and position_at_line against the whole program."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import REPO, XY_TABLE, XYZ_MILL

from controller.blocks import (
    NcBlock,
    NurbsBlock,
    OutputBlock,
    OutputChange,
    PathMode,
    Source,
    StopBlock,
    StopKind,
)
from controller.config import MachineConfig
from controller.errors import NcError
from controller.interpreter.program import position_at_line, read_program
from controller.offsets import OffsetTable, select, with_system

PROGRAMS = sorted((REPO / "nc_programs").glob("*.nc"))
MIXED = """\
(header)
G21 G90 G64 P0.02 F600
T2 M6
G0 X10 Y10
S1000 M3 M8
G92 X0 Y0
G1 X5 Y5

G2 X10 Y0 R6
G10 L2 P2 X20 Y-10
G55 G91 G1 X1 Y1 F300
G90 G5.2 L3
X5 Y5 P1

X10 Y0 P2
G5.3
G61 G0 X3
G6.2 P2 X3 Y0 K0
X8 Y0 K0
K1
(a comment inside the G6.2 block)
K1
M9
G53 G0 X0 Y0
G4 P0.5
M5
G92.1 G54 G1 X1
M2
G0 X100
"""


def key(block: NcBlock) -> object:
    """A comparable form of a block (NurbsBlock holds arrays)."""
    if isinstance(block, NurbsBlock):
        return (block.degree, block.control_points.tolist(), block.weights.tolist(),
                block.knots.tolist(), block.z_mm, block.feed_mm_s, block.path, block.source)
    return block


def expected_tail(full: list[NcBlock], n: int, config: MachineConfig = XYZ_MILL,
                  start: tuple | None = None) -> list[object] | str:
    """The blocks from line n on, or the reason from_line=n must be refused; led by the outputs
    the lines before n set, set again where line n starts (LinuxCNC's run from line)."""
    for b in full:
        if b.source.first_line < n <= b.source.last_line:
            return "inside"
    tail = [key(b) for b in full if b.source.first_line >= n]
    values: dict[str, object] = {}
    for b in full:
        if isinstance(b, OutputBlock) and b.source.first_line < n:
            values.update((c.name, c.value) for c in b.changes)
    if not values:
        return tail
    moved = [b.end for b in full if b.source.first_line < n and hasattr(b, "end")]
    where = moved[-1] if moved else (start or (0.0, 0.0, 0.0))
    wait = config.io.spindle.spin_up_s if values.get("spindle", "off") != "off" else 0.0
    path = full[0].source.path
    restore = OutputBlock(tuple(OutputChange(k, v) for k, v in values.items()),  # type: ignore[arg-type]
                          where, wait, Source(path, n, n))
    return [restore, *tail]


def check_every_line(path: Path, config: MachineConfig, offsets: OffsetTable | None = None,
                     start: tuple | None = None) -> None:
    full = list(read_program(str(path), config, start, offsets))
    lines = len(path.read_text().splitlines())
    ends = [b.source.first_line for b in full
            if isinstance(b, StopBlock) and b.kind in (StopKind.END, StopKind.END_REWIND)]
    stop = ends[0] if ends else lines  # the last line read
    for n in range(1, lines + 2):
        want = expected_tail(full, n, config, start)
        if want == "inside":
            with pytest.raises(NcError, match=f"cannot run from line {n}: it is inside the "
                                              f"G[56].2 NURBS block") as info:
                list(read_program(str(path), config, start, offsets, from_line=n))
            assert info.value.line == n
        elif n > stop:
            with pytest.raises(NcError, match=f"cannot run from line {n}: the program ends"):
                list(read_program(str(path), config, start, offsets, from_line=n))
        else:
            got = list(read_program(str(path), config, start, offsets, from_line=n))
            assert [key(b) for b in got] == want, n


@pytest.mark.parametrize("path", PROGRAMS, ids=lambda p: p.name)
def test_from_line_is_the_tail_of_every_example_program(path: Path) -> None:
    check_every_line(path, XYZ_MILL if path.name == "io_demo.nc" else XY_TABLE)  # Z, tools


def test_from_line_is_the_tail_of_a_program_with_offsets_nurbs_and_aux(tmp_path: Path) -> None:
    path = tmp_path / "mixed.nc"
    path.write_text(MIXED)
    check_every_line(path, XYZ_MILL)
    check_every_line(path, XYZ_MILL, select(with_system(OffsetTable(), 3, (5, 5, 5)), 3),
                     (1.0, 2.0, 3.0))


def test_from_line_one_is_the_whole_program(tmp_path: Path) -> None:
    path = tmp_path / "mixed.nc"
    path.write_text(MIXED)
    assert ([key(b) for b in read_program(str(path), XYZ_MILL, from_line=1)]
            == [key(b) for b in read_program(str(path), XYZ_MILL)])


LINES = st.lists(st.sampled_from([
    "G0 X{a} Y{b}", "G1 X{a} F{f}", "G91 G1 X{a} Y{b} F{f}", "G90", "G92 X{a}", "G92.1",
    "G10 L2 P{p} X{a} Y{b}", "G10 L20 P0 Y{b}", "G5{q}", "G2 X{a} Y{b} R100", "M3 S{f}",
    "(comment)", "", "G64 P0.01", "G61", "G4 P0.1", "G53 G0 X{b}", "M8", "M9",
]), min_size=1, max_size=25)


@settings(max_examples=40, deadline=None)
@given(LINES, st.lists(st.integers(1, 40), min_size=25, max_size=25), st.data())
def test_from_any_line_of_a_random_program_is_the_tail(lines: list[str], nums: list[int],
                                                       data: st.DataObject) -> None:
    text = "F100\n" + "\n".join(
        line.format(a=nums[i], b=-nums[-i - 1], f=nums[i] * 10, p=nums[i] % 7,
                    q=4 + nums[i] % 6) for i, line in enumerate(lines)) + "\n"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "p.nc"
        path.write_text(text)
        try:
            full = list(read_program(str(path), XYZ_MILL))
        except NcError:
            return  # e.g. an arc radius too small: nothing to compare
        n = data.draw(st.integers(1, len(lines) + 1))
        got = list(read_program(str(path), XYZ_MILL, from_line=n))
        assert [key(b) for b in got] == expected_tail(full, n)  # XYZ_MILL, from the origin
        state = position_at_line(str(path), XYZ_MILL, n)
        before = [b for b in full if b.source.first_line < n and hasattr(b, "end")]
        assert state.position_mm == (before[-1].end if before else (0.0, 0.0, 0.0))
        moves = [b for b in got if hasattr(b, "start")]
        if moves:
            assert moves[0].start == state.position_mm


def test_position_at_line_gives_the_modal_state(tmp_path: Path) -> None:
    path = tmp_path / "mixed.nc"
    path.write_text(MIXED)
    s = position_at_line(str(path), XYZ_MILL, 11)  # the G55 G91 line
    assert s.line == 11 and s.position_mm == (20.0, 10.0, 0.0)
    assert s.system == "G54" and s.offsets.systems_mm[1] == (20.0, -10.0, 0.0)
    assert s.offsets.g92_mm == (10.0, 10.0, 0.0) and s.program_position_mm == (10.0, 0.0, 0.0)
    assert s.feed_mm_s == 10.0 and s.distance_mode == "G90" and s.motion == "G2"
    assert s.path_control.mode is PathMode.BLEND and s.path_control.tolerance_mm == 0.02
    assert (s.spindle, s.spindle_rpm, s.coolant, s.tool) == ("M3", 1000.0, ("M8",), 2)
    s = position_at_line(str(path), XYZ_MILL, 12)
    assert s.system == "G55" and s.distance_mode == "G91" and s.feed_mm_s == 5.0
    assert s.position_mm == (21.0, 11.0, 0.0) and s.program_position_mm == (-9.0, 11.0, 0.0)
    s = position_at_line(str(path), XYZ_MILL, 23)  # after the G6.2 block, M9
    assert s.motion is None and s.path_control.mode is PathMode.EXACT_STOP
    assert s.position_mm == (38.0, 0.0, 0.0) and s.coolant == ("M8",)
    summary = s.summary()
    assert summary["offsets"]["active"] == "G55" and summary["coolant"] == ["M8"]
    assert position_at_line(str(path), XYZ_MILL, 24).coolant == ()


def test_the_state_inside_a_nurbs_block_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "mixed.nc"
    path.write_text(MIXED)
    for n, kind, first in ((13, "G5.2", 12), (16, "G5.2", 12), (19, "G6.2", 18),
                           (21, "G6.2", 18)):
        with pytest.raises(NcError) as info:
            position_at_line(str(path), XYZ_MILL, n)
        assert (info.value.line, info.value.word) == (n, kind)
        assert info.value.message.endswith(f"starts at line {first}; run from line {first}")


@pytest.mark.parametrize(("n", "message"), [
    (0, "lines are numbered from 1"), (-3, "lines are numbered from 1"),
    (29, "the program ends at line 28"), (500, "the program ends at line 28"),
])
def test_lines_outside_the_program_are_refused(tmp_path: Path, n: int, message: str) -> None:
    path = tmp_path / "mixed.nc"
    path.write_text(MIXED)
    with pytest.raises(NcError, match=message) as info:
        list(read_program(str(path), XYZ_MILL, from_line=n))
    assert info.value.line == n


def test_errors_before_line_n_are_still_reported(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    path.write_text("G0 X1\nG1 X2\nG0 X3\n")  # G1 with no feed on line 2
    with pytest.raises(NcError, match="no feed rate") as info:
        list(read_program(str(path), XY_TABLE, from_line=3))
    assert info.value.line == 2


def test_a_g6_2_block_ended_by_the_end_of_the_file(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    path.write_text("F60\nG6.2 P2 X0 Y0 K0\nX8 Y0 K0\nK1\nK1\n\n(end)\n")
    assert list(read_program(str(path), XY_TABLE, from_line=6)) == []
    assert np.array_equal(position_at_line(str(path), XY_TABLE, 7).position_mm, (8, 0, 0))
