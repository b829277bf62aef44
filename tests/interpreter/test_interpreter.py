"""Interpreter features: units, distance modes, feeds, arcs, path control, dwell, M codes, Z."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of, motion

from controller.blocks import (
    ArcBlock,
    DwellBlock,
    LineBlock,
    OutputBlock,
    PathMode,
    StopBlock,
    StopKind,
)
from controller.errors import NcError
from controller.interpreter.program import read_program


def test_rapid_and_feed_lines_in_mm_and_mm_per_s(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G21 G90\nG0 X10 Y5\nG1 X20 F600\n")
    assert b[0] == LineBlock((0.0, 0.0, 0.0), (10.0, 5.0, 0.0),
                             XY_TABLE.interpolator.rapid_feed_mm_s, True, b[0].path, b[0].source)
    assert b[1].end == (20.0, 5.0, 0.0) and b[1].feed_mm_s == pytest.approx(10.0)
    assert not b[1].rapid and b[1].source.first_line == 3


def test_inches_scale_coordinates_and_feed(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G20\nG1 X1 Y-2 F60\n")
    assert b[0].end == pytest.approx((25.4, -50.8, 0.0))
    assert b[0].feed_mm_s == pytest.approx(25.4)


def test_incremental_mode_and_modal_motion(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G91 G1 X1 Y1 F60\nX1\nY-3\n")
    assert [blk.end for blk in b] == [(1, 1, 0), (2, 1, 0), (2, -2, 0)]


def test_zero_length_move_yields_nothing(tmp_path: Path) -> None:
    assert blocks_of(tmp_path, "G0 X0 Y0\nG1 X0 F100\n") == []


def test_arc_ij_incremental_centre_and_direction(tmp_path: Path) -> None:
    (a,) = blocks_of(tmp_path, "G1 X10 F60\nG1 X10 Y0\nG3 X0 Y10 I-10 J0\n")[1:]
    assert isinstance(a, ArcBlock) and a.center == (0.0, 0.0) and not a.clockwise
    assert a.sweep_rad == pytest.approx(math.pi / 2)
    assert a.length_mm == pytest.approx(5 * math.pi)


def test_arc_absolute_centre_g90_1(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "F60 G90.1\nG1 X10\nG2 X0 Y-10 I0 J0\n")
    assert b[1].center == (0.0, 0.0) and b[1].clockwise
    assert b[1].sweep_rad == pytest.approx(-math.pi / 2)


@pytest.mark.parametrize(("word", "g", "sweep"), [
    ("R5", "G2", -math.pi), ("R5", "G3", math.pi),
    ("R7.0710678", "G2", -math.pi / 2), ("R-7.0710678", "G2", -3 * math.pi / 2),
    ("R7.0710678", "G3", math.pi / 2), ("R-7.0710678", "G3", 3 * math.pi / 2),
])
def test_arc_r_form_picks_the_right_centre(tmp_path: Path, word: str, g: str,
                                           sweep: float) -> None:
    end = "X10 Y0" if word == "R5" else "X10 Y0"
    (a,) = blocks_of(tmp_path, f"F60\n{g} {end} {word}\n")
    assert a.sweep_rad == pytest.approx(sweep, abs=1e-6)
    r = abs(float(word[1:]))
    assert a.radius_mm == pytest.approx(r, abs=1e-6)
    assert math.hypot(10 - a.center[0], a.center[1]) == pytest.approx(r, abs=1e-6)


def test_full_circle_and_extra_turns(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "F60\nG1 X10\nG2 I-10\nG3 I-10 P3\n")
    assert b[1].start == b[1].end and b[1].sweep_rad == pytest.approx(-2 * math.pi)
    assert b[2].turns == 2 and b[2].sweep_rad == pytest.approx(6 * math.pi)


def test_radius_difference_within_linuxcnc_tolerance_is_accepted(tmp_path: Path) -> None:
    (a,) = blocks_of(tmp_path, "F60\nG2 X60.02 Y0 I30\n")  # 0.02 mm < 0.0283 mm and < 0.1 %
    assert a.end == (60.02, 0.0, 0.0)
    (b,) = blocks_of(tmp_path, "F60\nG2 X20.02 Y0 I10\n")  # 0.2 % but under 0.0283 mm
    assert b.end == (20.02, 0.0, 0.0)
    with pytest.raises(NcError, match="differs"):  # 0.03 mm is 0.3 % of 10 mm: both over
        blocks_of(tmp_path, "F60\nG2 X20.03 Y0 I10\n")


def test_path_control_modes(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "F60\nG1 X1\nG64 P0.02 Q0.01 X2\nG61 X3\nG61.1 X4\nG64 X5\n"
                            "G20 G64 P0.001 X6\n")
    assert b[0].path.mode is PathMode.BLEND and b[0].path.tolerance_mm is None
    assert (b[1].path.tolerance_mm, b[1].path.naive_cam_tolerance_mm) == (0.02, 0.01)
    assert b[2].path.mode is PathMode.EXACT_STOP
    assert b[3].path.mode is PathMode.EXACT_PATH
    assert b[4].path.mode is PathMode.BLEND and b[4].path.tolerance_mm is None
    assert b[5].path.tolerance_mm == pytest.approx(0.0254)


def test_dwell_aux_and_stop_blocks_in_linuxcnc_order(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "T3 M6\nS1200 M3 M8 G4 P0.5 G0 X1 M0\nS900\nM5 M9\nM2\nG0 X50\n")
    kinds = [(type(x).__name__, getattr(x, "code", getattr(x, "kind", None))) for x in b]
    # M6 is a manual tool change: a pause for the operator (no change position configured)
    assert kinds == [("AuxBlock", "M6"), ("StopBlock", StopKind.PAUSE), ("OutputBlock", None),
                     ("DwellBlock", None), ("LineBlock", None), ("StopBlock", StopKind.PAUSE),
                     ("OutputBlock", None), ("OutputBlock", None), ("StopBlock", StopKind.END)]
    assert b[0].tool == 3
    assert [(c.name, c.value) for c in b[2].changes] == [
        ("spindle_rpm", 1200.0), ("spindle", "cw"), ("coolant_flood", True)]
    assert [(c.name, c.value) for c in b[6].changes] == [("spindle_rpm", 900.0)]
    assert [(c.name, c.value) for c in b[7].changes] == [
        ("spindle", "off"), ("coolant_mist", False), ("coolant_flood", False)]
    assert isinstance(b[3], DwellBlock) and b[3].seconds == 0.5
    assert isinstance(b[-1], StopBlock) and b[-1].position == (1.0, 0.0, 0.0)


def test_harmless_header_codes_are_accepted(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G17 G21 G40 G49 G54 G80 G90 G94 G97 G98\nG43 H1\nG96 S200 M3\n"
                            "G0 X1\n")
    # G96: S is a surface speed, not an rpm for the spindle's speed output
    assert isinstance(b[0], OutputBlock) and [c.name for c in b[0].changes] == ["spindle"]
    assert b[-1].end == (1.0, 0.0, 0.0)


def test_mist_and_flood_together(tmp_path: Path) -> None:
    (block,) = blocks_of(tmp_path, "M7 M8\n")
    assert [(c.name, c.value) for c in block.changes] == [("coolant_mist", True),
                                                          ("coolant_flood", True)]


def test_parameters_set_after_the_line(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "#1=60\n#2=#1 F#1\nG1 X#2\n#1=120 G1 X#1\n")
    assert b[0].end == (60.0, 0.0, 0.0) and b[0].feed_mm_s == 1.0
    # #1 is set after line 4 is read, so X#1 on that line still sees 60: no motion at all
    assert len(b) == 1


def test_percent_delimits_the_program(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "%\nG0 X1\n%\nthis is not read\n")
    assert [x.end for x in b] == [(1.0, 0.0, 0.0)]


def test_z_moves_on_the_mill_are_lines(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G0 Z5\nG1 X10 Z-1 F60\nG2 X20 I5\n", XYZ_MILL)
    assert b[1].end == (10.0, 0.0, -1.0) and b[2].start[2] == -1.0 == b[2].end[2]


def test_z_word_that_does_not_move_is_fine_on_the_table(tmp_path: Path) -> None:
    assert blocks_of(tmp_path, "G0 X1 Z0\n")[0].end == (1.0, 0.0, 0.0)


def test_missing_file_is_an_nc_error() -> None:
    with pytest.raises(NcError, match="cannot open program"):
        list(read_program("/nonexistent/prog.nc", XY_TABLE))


def test_streaming_yields_before_the_end_of_the_file(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    path.write_text("F60\nG1 X1\nG1 X2\nG1 X3 Q\n")
    blocks = read_program(str(path), XY_TABLE)
    assert next(blocks).end == (1.0, 0.0, 0.0)  # read before the bad line 4 is reached
    with pytest.raises(NcError) as info:
        list(blocks)
    assert info.value.line == 4


def test_crlf_and_no_final_newline(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    path.write_bytes(b"F60\r\nG1 X1\r\nG1 X2")
    assert [b.end[0] for b in motion(list(read_program(str(path), XY_TABLE)))] == [1.0, 2.0]


def _peak_bytes_reading(path: Path) -> int:
    import tracemalloc

    tracemalloc.start()
    for _ in read_program(str(path), XY_TABLE):
        pass
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def test_memory_does_not_grow_with_program_length(tmp_path: Path) -> None:
    peaks = []
    for n in (10_000, 40_000):  # both longer than one 64 k read chunk
        path = tmp_path / f"p{n}.nc"
        path.write_text("F600\n" + "".join(f"G1 X{i % 90}.5 Y{i % 13}\nG2 X{i % 90}.5 Y{i % 13 + 2}"
                                           f" R1.5\n" for i in range(n // 2)))
        peaks.append(_peak_bytes_reading(path))
    assert peaks[1] < 1.1 * peaks[0]  # four times the lines, the same peak
