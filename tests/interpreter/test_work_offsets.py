"""Work offsets in the interpreter: G54-G59, G10 L2/L20, G92/G92.1/G92.2, G53, travel."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE, XYZ_MILL, motion

from controller.blocks import ArcBlock, LineBlock, NurbsBlock
from controller.config import MachineConfig
from controller.errors import NcError
from controller.interpreter.extent import TravelLimits, line_length_and_box
from controller.interpreter.program import final_offsets, read_program
from controller.offsets import (
    OffsetTable,
    ProgramOffsets,
    select,
    with_g92,
    with_system,
    work_origin_mm,
)
from controller.operator.check_cmd import check_program


def run(tmp_path: Path, text: str, config: MachineConfig = XYZ_MILL,
        offsets: OffsetTable | None = None, start: tuple | None = None
        ) -> tuple[list, OffsetTable]:
    """Blocks of a program and the table it leaves."""
    path = tmp_path / "prog.nc"
    path.write_text(text, encoding="utf-8")
    track = ProgramOffsets()
    blocks = list(read_program(str(path), config, start, offsets, track=track))
    return blocks, track.table


def ends(blocks: list) -> list[tuple[float, float, float]]:
    return [b.end for b in motion(blocks)]


COORD = st.floats(min_value=-60, max_value=60, allow_nan=False).map(lambda v: round(v, 4))
POINT = st.tuples(COORD, COORD, COORD)


@settings(max_examples=60, deadline=None)
@given(systems=st.tuples(*[POINT] * 6), g92=POINT, active=st.integers(1, 6),
       points=st.lists(POINT, min_size=1, max_size=8, unique=True), inch=st.booleans())
def test_program_coordinates_plus_origin_are_the_machine_coordinates(
        systems: tuple, g92: tuple, active: int, points: list, inch: bool) -> None:
    table = OffsetTable(systems, g92, active)
    scale = 25.4 if inch else 1.0
    text = ("G20" if inch else "G21") + " F600\n" + "".join(
        f"G{i % 2} X{x:.4f} Y{y:.4f} Z{z:.4f}\n" for i, (x, y, z) in enumerate(points))
    with tempfile.TemporaryDirectory() as tmp:  # start away from every programmed point
        blocks, after = run(Path(tmp), text, offsets=table, start=(-500.0, -500.0, -500.0))
    assert after == table
    origin = work_origin_mm(table)
    assert len(blocks) == len(points)
    for block, point in zip(blocks, points, strict=True):
        assert np.allclose(np.array(block.end) - origin, np.array(point) * scale,
                           rtol=0, atol=1e-9)
    assert all(a.end == b.start for a, b in zip(blocks, blocks[1:], strict=False))


def test_g54_to_g59_select_the_stored_origins(tmp_path: Path) -> None:
    table = OffsetTable(tuple((10.0 * n, -n, 0.5 * n) for n in range(1, 7)))
    blocks, after = run(tmp_path, "G0 X1 Y1 Z1\nG55 X1 Y1 Z1\nG59 X1 Y1 Z1\nG54 X0\n",
                        offsets=table)
    assert ends(blocks) == [(11, 0, 1.5), (21, -1, 2), (61, -5, 4), (10, -5, 4)]
    assert after.active_name == "G54" and after.systems_mm == table.systems_mm


def test_g10_l2_sets_only_the_axes_given_in_machine_coordinates(tmp_path: Path) -> None:
    blocks, after = run(tmp_path, "G10 L2 P1 X10 Y20\nG0 X1 Y1\nG10 L2 P0 Y5\nG0 X1 Y1\n"
                                  "G10 L2 P3 Z-7\nG91 G10 L2 P2 X3\nG10 L2 P2 X3\n")
    assert ends(blocks) == [(11, 21, 0), (11, 6, 0)]
    assert after.systems_mm[:3] == ((10, 5, 0), (3, 0, 0), (0, 0, -7))  # G91: no effect


def test_g10_l2_in_inches_and_on_an_inactive_system(tmp_path: Path) -> None:
    blocks, after = run(tmp_path, "G20\nG10 L2 P2 X1\nG0 X1\nG55 X1\n")
    assert ends(blocks) == [(25.4, 0, 0), (50.8, 0, 0)]
    assert after.systems_mm[1] == (25.4, 0, 0) and after.active == 2


def test_g10_l20_makes_the_current_position_read_the_values(tmp_path: Path) -> None:
    # at machine (10, 20, 0): G55 is set so that this point reads X1 Y2 there
    blocks, after = run(tmp_path, "G0 X10 Y20\nG10 L20 P2 X1 Y2\nG55 G0 X0 Y0\n")
    assert after.systems_mm[1] == (9.0, 18.0, 0.0)
    assert ends(blocks)[-1] == (9.0, 18.0, 0.0)


def test_g10_l20_is_absolute_under_g91_and_subtracts_g92(tmp_path: Path) -> None:
    text = "G91 G0 X10 Y10\nG92 X0\nG10 L20 P0 X3 Y4\nG90 G0 X3 Y4\nG0 X0 Y0\n"
    blocks, after = run(tmp_path, text)
    # G92 X0 at machine X10: g92 x = 10. L20 P0 (G54): origin x = 10 - 10 - 3 = -3,
    # origin y = 10 - 0 - 4 = 6; program (0, 0) = machine (-3 + 10, 6 + 0)
    assert after.g92_mm == (10, 0, 0) and after.systems_mm[0] == (-3, 6, 0)
    assert ends(blocks) == [(10, 10, 0), (7, 6, 0)]


def test_g92_follows_linuxcnc_example(tmp_path: Path) -> None:
    # LinuxCNC's G92 text: at X4 with no offset, G92 X7 makes the offset -3; then G92 X9: -5
    _, after = run(tmp_path, "G0 X4\nG92 X7\n")
    assert after.g92_mm == (-3, 0, 0)
    blocks, after = run(tmp_path, "G0 X4\nG92 X7\nG92 X9\nG0 X10\n")
    assert after.g92_mm == (-5, 0, 0) and ends(blocks)[-1] == (5, 0, 0)


def test_g92_is_absolute_under_g91_and_applies_to_every_system(tmp_path: Path) -> None:
    table = with_system(OffsetTable(), 2, (100, 0, 0))
    blocks, after = run(tmp_path, "G91 G0 X5 Y5\nG92 X0 Y0\nX1\nG90 G55 X0 Y0\n",
                        offsets=table)
    assert after.g92_mm == (5, 5, 0)
    assert ends(blocks) == [(5, 5, 0), (6, 5, 0), (105, 5, 0)]


@pytest.mark.parametrize("clear", ["G92.1", "G92.2"])
def test_g92_1_and_g92_2_clear_the_offset(tmp_path: Path, clear: str) -> None:
    blocks, after = run(tmp_path, f"G0 X4\nG92 X0\nG0 X1\n{clear}\nG0 X1\n")
    assert after.g92_mm == (0, 0, 0) and ends(blocks) == [(4, 0, 0), (5, 0, 0), (1, 0, 0)]


def test_g53_moves_in_machine_coordinates_for_one_line(tmp_path: Path) -> None:
    table = select(with_system(OffsetTable(), 2, (100, 50, 0)), 2)
    blocks, _ = run(tmp_path, "F600\nG1 X0 Y0\nG53 G0 X5 Y5\nX1\nG53 X3\nG1 G53 Y7\nG91 G53 X1\n",
                    offsets=table)
    assert ends(blocks) == [(100, 50, 0), (5, 5, 0), (101, 5, 0), (3, 5, 0), (3, 7, 0),
                            (4, 7, 0)]
    assert blocks[1].rapid and not blocks[4].rapid


def test_arcs_and_nurbs_are_shifted_by_the_origin(tmp_path: Path) -> None:
    table = OffsetTable(g92_mm=(100.0, 50.0, 0.0))
    text = ("F600\nG0 X10 Y0\nG3 X0 Y10 I-10 J0\nG90.1 G2 X10 Y0 I0 J0\nG3 X0 Y10 R10\n"
            "G5.2 L3\nX5 Y5 P1\nX10 Y0 P1\nG5.3\n"
            "G6.2 P2 X10 Y0 K0\nX20 Y0 K0\nK1\nK1\nG0 X0\n")
    blocks, _ = run(tmp_path, text, offsets=table)
    arcs = [b for b in blocks if isinstance(b, ArcBlock)]
    assert [a.center for a in arcs] == [(100, 50)] * 3
    nurbs = [b for b in blocks if isinstance(b, NurbsBlock)]
    assert np.array_equal(nurbs[0].control_points, [[100, 60], [105, 55], [110, 50]])
    assert np.array_equal(nurbs[1].control_points, [[110, 50], [120, 50]])


def test_g6_2_first_point_message_is_in_program_coordinates(tmp_path: Path) -> None:
    with pytest.raises(NcError, match=r"current position X10\.0000 Y0\.0000"):
        run(tmp_path, "F600\nG0 X10\nG6.2 P2 X0 Y0 K0\n", offsets=OffsetTable(g92_mm=(5, 0, 0)))


def test_nurbs_z_is_checked_in_the_program_frame(tmp_path: Path) -> None:
    table = OffsetTable(g92_mm=(0, 0, 5))
    blocks, _ = run(tmp_path, "F600\nG5.2 L2 Z0\nX1 Y1 P1\nG5.3\n", offsets=table,
                    start=(0, 0, 5))
    assert blocks[0].z_mm == 5


def test_z_offsets_on_the_table_without_z(tmp_path: Path) -> None:
    blocks, after = run(tmp_path, "G92 X0 Y0 Z0\nG10 L20 P1 Z0\nG0 X1 Z0\n", XY_TABLE)
    assert ends(blocks) == [(1, 0, 0)] and after == OffsetTable()
    with pytest.raises(NcError, match="Z offset on a machine without a Z axis") as info:
        run(tmp_path, "G0 X1\nG92 Z3\n", XY_TABLE)
    assert (info.value.line, info.value.col, info.value.word) == (2, 5, "Z3")


@pytest.mark.parametrize(("text", "line", "col", "word"), [
    ("G10 L2 P1 X0\nG10 L3 P1\n", 2, 5, "L3"),
    ("(x)\n  G92  X1 G0\n", 2, 3, "G92"),
    ("G0 X1\nG59.3\n", 2, 1, "G59.3"),
    ("F1\nG2 X1 R1\nG53 Y1\n", 3, 1, "G53"),
    ("G4 P1 G92 X1\n", 1, 7, "G92"),
])
def test_errors_name_line_column_and_word(tmp_path: Path, text: str, line: int, col: int,
                                          word: str) -> None:
    with pytest.raises(NcError) as info:
        run(tmp_path, text)
    assert (info.value.line, info.value.col, info.value.word) == (line, col, word)


def test_g80_with_g92_cancels_the_motion_mode(tmp_path: Path) -> None:
    with pytest.raises(NcError, match="no motion mode"):
        run(tmp_path, "G0 X1\nG80 G92 X0\nX5\n")


def test_the_track_and_final_offsets_give_the_table_after_the_program(tmp_path: Path) -> None:
    text = "G10 L2 P3 X7\nG56\nG0 X1\nG92 Y2\nM2\nG10 L2 P3 X8\n"
    start = with_system(OffsetTable(), 6, (1, 2, 3))
    _, after = run(tmp_path, text, offsets=start)
    path = tmp_path / "prog.nc"
    assert final_offsets(str(path), XYZ_MILL, None, start) == after
    # M2 stops reading (line 6 is not read) and selects G54 again; the G92 offset stays
    assert after.active_name == "G54" and after.systems_mm[2] == (7, 0, 0)
    assert after.systems_mm[5] == (1, 2, 3) and after.g92_mm == (0, -2, 0)
    _, after = run(tmp_path, "G56\nG0 X1\n")
    assert after.active_name == "G56"  # no M2: the last selection stays


def _travel_blocks(tmp_path: Path, text: str, table: OffsetTable) -> None:
    path = tmp_path / "prog.nc"
    path.write_text(text)
    limits = TravelLimits(XY_TABLE)
    track = ProgramOffsets()
    for block in read_program(str(path), XY_TABLE, None, table, track=track):
        if isinstance(block, LineBlock):
            limits.check(str(path), block, line_length_and_box(block)[1], track.table)


def test_a_g55_offset_that_leaves_the_travel_is_refused_before_motion(tmp_path: Path) -> None:
    text = "G0 X10 Y10\nG55 G0 X60 Y0\n"
    _travel_blocks(tmp_path, text, OffsetTable())  # fine without the offset
    table = with_g92(with_system(OffsetTable(), 2, (100, 0, 0)), (0, 5, 0))
    with pytest.raises(NcError) as info:
        _travel_blocks(tmp_path, text, table)
    assert (info.value.line, info.value.word) == (2, "X")
    assert info.value.message == (
        "X travel limit exceeded: the path reaches 160.0000 mm in machine coordinates "
        "(X60.0000 mm in the program's G55 + G92 frame), travel is [-150, 150] mm")
    with pytest.raises(NcError, match=r"reaches -151\.0000 mm in machine coordinates, travel"):
        _travel_blocks(tmp_path, "G0 X-151\n", OffsetTable())


def test_an_offset_set_in_the_program_is_refused_by_check(tmp_path: Path) -> None:
    path = tmp_path / "prog.nc"
    path.write_text("G0 X10\nG10 L2 P2 X100\nG55 G0 X60\n")
    with pytest.raises(NcError, match="X travel limit exceeded") as info:
        check_program(str(path), XY_TABLE)
    assert info.value.line == 3


@pytest.mark.parametrize("suffix", ["", " (comment: the general path)", " M8"])
def test_every_path_of_a_line_applies_the_offsets(tmp_path: Path, suffix: str) -> None:
    table = OffsetTable(((1.0, 2.0, 3.0),) * 6, (10.0, 20.0, 30.0), 4)
    text = "".join(f"{line}{suffix}\n" for line in
                   ("F600", "G1 X1 Y1 Z1", "X2", "G0 Y5", "G2 X4 Y5 R1", "G91 G0 X1", "G90 G1 Z0"))
    blocks, _ = run(tmp_path, text, offsets=table)
    assert ends(blocks) == [(12, 23, 34), (13, 23, 34), (13, 27, 34), (15, 27, 34),
                            (16, 27, 34), (16, 27, 33)]
