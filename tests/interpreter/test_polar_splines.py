"""Polar coordinates (@ radius, ^ angle) and G5.1 quadratic splines, as LinuxCNC reads them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from nc_helpers import LINUXCNC_START, XYZ_MILL, blocks_of, mill_with_gcode

from controller.blocks import ArcBlock, LineBlock, NurbsBlock, ProbeBlock
from controller.errors import NcError
from controller.geometry.nurbs import Nurbs
from controller.interpreter.program import read_program
from controller.offsets import ProgramOffsets


def _polar(radius: float, angle_deg: float) -> tuple[float, float]:
    return radius * math.cos(math.radians(angle_deg)), radius * math.sin(math.radians(angle_deg))


def _ends(tmp_path: Path, text: str) -> list[tuple[float, float, float]]:
    return [b.end for b in blocks_of(tmp_path, text, XYZ_MILL) if hasattr(b, "end")]


def _close(got: object, want: object) -> None:
    np.testing.assert_allclose(np.array(got, dtype=float), np.array(want, dtype=float), atol=1e-9)


def _refused(tmp_path: Path, text: str) -> NcError:
    with pytest.raises(NcError) as info:
        blocks_of(tmp_path, text, XYZ_MILL)
    return info.value


def test_g90_radius_and_angle_from_the_work_origin(tmp_path: Path) -> None:
    ends = _ends(tmp_path, "G21 G90 G0 X10 Y0\nG1 F100 @5 ^90\n^180\n@20\n")
    _close([e[:2] for e in ends[1:]], [_polar(5, 90), _polar(5, 180), _polar(20, 180)])


def test_g91_adds_to_the_radius_and_angle_about_the_work_origin(tmp_path: Path) -> None:
    """Not about the current point: G91 @-1 moves toward the origin, G91 ^ turns about it."""
    ends = _ends(tmp_path, "G21 G90 G0 X10 Y0\nG91 G1 F100 @-4\n^135\n@2 ^-45\n")
    _close([e[:2] for e in ends[1:]], [_polar(6, 0), _polar(6, 135), _polar(8, 90)])


def test_polar_words_are_in_the_work_frame_and_program_units(tmp_path: Path) -> None:
    text = "G21 G10 L2 P2 X100 Y50\nG55 G0 @10 ^90\nG20 G0 @1 ^0\n"
    ends = _ends(tmp_path, text)
    assert ends[0][:2] == pytest.approx((100.0, 60.0))
    assert ends[1][:2] == pytest.approx((125.4, 50.0))


def test_a_polar_line_may_move_z(tmp_path: Path) -> None:
    (_, end) = _ends(tmp_path, "G21 G0 X3 Y4\nG1 F60 @10 Z-2\n")
    assert end == pytest.approx((6.0, 8.0, -2.0))


def test_an_arc_ends_at_its_polar_point(tmp_path: Path) -> None:
    blocks = blocks_of(tmp_path, "G21 G0 X10 Y0\nG3 F100 @10 ^90 I-10 J0\n", XYZ_MILL)
    arc = blocks[-1]
    assert isinstance(arc, ArcBlock) and not arc.clockwise
    assert arc.end[:2] == pytest.approx(_polar(10, 90)) and arc.center == pytest.approx((0, 0))


def test_a_probe_goes_to_its_polar_point(tmp_path: Path) -> None:
    probe = blocks_of(tmp_path, "G21 G0 X1 Y1\nG38.3 F10 @5\n", XYZ_MILL)[-1]
    assert isinstance(probe, ProbeBlock) and probe.end[:2] == pytest.approx(_polar(5, 45))


def test_a_g91_cycle_turns_every_repeat_about_the_origin(tmp_path: Path) -> None:
    """LinuxCNC's hole-circle.ngc: G91 G81 ^60 L6 drills six holes on a circle."""
    text = "G21 G0 X15 Y0 Z5\nG91 G81 R-3 Z-2 ^60 L6 F100\n"
    feeds = [
        b for b in blocks_of(tmp_path, text, XYZ_MILL) if isinstance(b, LineBlock) and not b.rapid
    ]
    holes = [b.end for b in feeds]
    _close(holes, [(*_polar(15, 60 * k), 0.0) for k in range(1, 7)])


def test_a_g90_cycle_line_of_polar_words_drills_there(tmp_path: Path) -> None:
    text = "G21 G0 X25 Y0 Z10\nG81 R2 Z-3 F200\n^72\n@30 ^216\n"
    feeds = [
        b for b in blocks_of(tmp_path, text, XYZ_MILL) if isinstance(b, LineBlock) and not b.rapid
    ]
    _close([b.end[:2] for b in feeds], [(25, 0), _polar(25, 72), _polar(30, 216)])


def test_the_lexer_reads_expressions_and_parameters_after_polar_words(tmp_path: Path) -> None:
    ends = _ends(tmp_path, "G21 #1 = 4\nG0 @#1 ^[360/8]\nG91 @-.5\n")
    _close([e[:2] for e in ends], [_polar(4, 45), _polar(3.5, 45)])


@pytest.mark.parametrize(
    ("text", "word", "message"),
    [
        ("G21 G0 X1 Y1\nG1 F100 @5 X3\n", "X", "X word with polar coordinates"),
        ("G21 G0 X1 Y1\nG1 F100 ^5 Y3\n", "Y", "Y word with polar coordinates"),
        ("G21 G0 X1 Y1\nG18 G1 F100 ^5\n", "^", "only in the XY plane (G17)"),
        ("G21 G0 X1 Y1\nG28 @5\n", "@", "can only be used for motion"),
        ("G21 G0 X1 Y1\nG92 ^5\n", "^", "can only be used for motion"),
        ("G21 G0 X1 Y1\nG10 L20 P1 @5\n", "@", "can only be used for motion"),
        ("G21 G0 X1 Y1\nG80 @5\n", "@", "can only be used for motion"),
        ("G21 G0 X1 Y1\nG53 G1 F100 @5\n", "@", "cannot be used with G53"),
        ("G21 G0 X0 Y0\nG1 F100 @5\n", "@", "the angle is undefined"),
        ("G21 G0 X0 Y0\nG91 G1 F100 ^5\n", "^", "at the work origin"),
        ("G21 G0 X0 Y0 Z5\nG91 G81 R-3 Z-2 ^60 L6 F100\n", "^", "at the work origin"),
    ],
)
def test_misused_polar_words_are_refused_naming_the_word(
    tmp_path: Path, text: str, word: str, message: str
) -> None:
    err = _refused(tmp_path, text)
    assert err.line == 2 and message in err.message
    assert err.word.startswith(word)
    assert text.splitlines()[1][err.col - 1] == word  # the column points at the word


def test_g90_angle_alone_at_the_origin_stays_there(tmp_path: Path) -> None:
    """LinuxCNC's rule: radius 0 at any angle is the origin (a zero-length move)."""
    assert _ends(tmp_path, "G21 G1 F100 ^30\nG1 X1\n") == [(1.0, 0.0, 0.0)]


# ---- G5.1 ---------------------------------------------------------------------------------
def test_g5_1_is_the_order_3_nurbs_of_start_control_and_end(tmp_path: Path) -> None:
    (block,) = blocks_of(tmp_path, "G21 G0 X1 Y2\nG5.1 F120 X10 Y1 I4 J5\n", XYZ_MILL)[1:]
    assert isinstance(block, NurbsBlock) and block.degree == 2
    np.testing.assert_array_equal(block.control_points, [[1, 2], [5, 7], [10, 1]])
    np.testing.assert_array_equal(block.weights, [1, 1, 1])
    np.testing.assert_array_equal(block.knots, [0, 0, 0, 1, 1, 1])
    assert block.feed_mm_s == pytest.approx(2.0)
    u = np.linspace(0, 1, 11)
    p0, p1, p2 = (np.array(p) for p in ([1, 2], [5, 7], [10, 1]))
    bezier = np.outer((1 - u) ** 2, p0) + np.outer(2 * u * (1 - u), p1) + np.outer(u**2, p2)
    np.testing.assert_allclose(Nurbs.from_block(block).evaluate(u, 0)[0], bezier, atol=1e-12)


def test_g5_1_is_the_same_block_as_g5_2_of_its_three_points(tmp_path: Path) -> None:
    (a,) = blocks_of(tmp_path, "G21 G0 X1 Y2\nG5.1 F120 X10 Y1 I4 J5\n", XYZ_MILL)[1:]
    g5_2 = "G21 G0 X1 Y2\nF120\nG5.2 L3\nX5 Y7 P1\nX10 Y1 P1\nG5.3\n"
    (b,) = blocks_of(tmp_path, g5_2, XYZ_MILL)[1:]
    for name in ("control_points", "weights", "knots"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert (a.degree, a.z_mm, a.feed_mm_s) == (b.degree, b.z_mm, b.feed_mm_s)


def test_g5_1_in_g91_inches_with_an_offset_and_a_polar_end(tmp_path: Path) -> None:
    text = (
        "G21 G10 L2 P2 X5 Y-5\nG55 G0 X0 Y0\nG20 G91 G5.1 F10 X1 Y2 I0.5 J0\n"
        "G21 G90 G5.1 @10 ^90 I-1 J1\n"
    )
    first, second = blocks_of(tmp_path, text, XYZ_MILL)[1:]
    np.testing.assert_allclose(first.control_points, [[5, -5], [17.7, -5], [30.4, 45.8]])
    np.testing.assert_allclose(second.control_points, [[30.4, 45.8], [29.4, 46.8], [5, 5]])


def test_g5_1_leaves_the_motion_mode_in_force_before_it(tmp_path: Path) -> None:
    """LinuxCNC's rs274: an axis line after G5.1 runs in the G0 or G1 in force before it."""
    blocks = blocks_of(tmp_path, "G21 G0 X1 Y1\nG5.1 F100 X5 Y1 I2 J2\nX7 Y0\n", XYZ_MILL)
    assert isinstance(blocks[-1], LineBlock) and blocks[-1].rapid
    assert blocks[-1].start == (5.0, 1.0, 0.0)


@pytest.mark.parametrize(
    ("text", "word", "message"),
    [
        ("G21 G0 X1 Y1\nG5.1 F100 X5 Y1 Z3 I2 J2\n", "Z", "constant Z"),
        ("G21 G0 X1 Y1\nG5.1 F100 X5 Y1 I2\n", "I", "both I and J"),
        ("G21 G0 X1 Y1\nG5.1 F100 X5 Y1 J2\n", "J", "both I and J"),
        ("G21 G0 X1 Y1\nG5.1 F100 I2 J2\n", "G5.1", "needs its end point"),
        ("G21 G0 X1 Y1\nG18 G5.1 F100 X5 Y1 I2 J2\n", "G5.1", "XY plane (G17) only"),
    ],
)
def test_misused_g5_1_is_refused_naming_the_word(
    tmp_path: Path, text: str, word: str, message: str
) -> None:
    err = _refused(tmp_path, text)
    assert err.line == 2 and message in err.message and err.word.startswith(word)


def test_g5_1_without_motion_is_no_block(tmp_path: Path) -> None:
    assert blocks_of(tmp_path, "G21 G0 X1 Y1\nG5.1 F100 X1 Y1 I0 J0\n", XYZ_MILL)[1:] == []


def _with_warnings(tmp_path: Path, text: str, gcode: object) -> tuple[list, list[str]]:
    prog = tmp_path / "prog.nc"
    prog.write_text(text)
    track = ProgramOffsets()
    config = mill_with_gcode(tmp_path, gcode)
    return list(read_program(str(prog), config, track=track)), track.warnings


def test_g5_1_needs_a_feed_where_linuxcnc_does(tmp_path: Path) -> None:
    with pytest.raises(NcError, match="G5.1 feed move with no feed rate") as info:
        _with_warnings(tmp_path, "G21 G0 X1 Y1\nG5.1 X5 Y1 I2 J2\nM2\n", LINUXCNC_START)
    assert info.value.line == 2 and info.value.word == "G5.1"


def test_g5_1_before_any_f_moves_at_the_default_feed_with_a_warning(tmp_path: Path) -> None:
    gcode = {"default_feed_mm_min": 90.0}
    blocks, warnings = _with_warnings(tmp_path, "G21 G0 X1 Y1\nG5.1 X5 Y1 I2 J2\nM2\n", gcode)
    (spline,) = [b for b in blocks if isinstance(b, NurbsBlock)]
    assert spline.feed_mm_s == pytest.approx(1.5)
    assert len(warnings) == 1 and ":2: G5.1: no F programmed yet" in warnings[0]


def test_a_polar_line_under_the_power_up_g0_moves_at_rapid_and_says_so(tmp_path: Path) -> None:
    text = "G21 G90\n@5 ^90\nM2\n"
    blocks, warnings = _with_warnings(tmp_path, text, {"power_up_motion": "G0"})
    (line,) = [b for b in blocks if isinstance(b, LineBlock)]
    assert line.rapid and line.end == pytest.approx((0.0, 5.0, 0.0))
    assert len(warnings) == 1 and ":2: @: no motion mode programmed yet" in warnings[0]


def test_a_g17_on_the_polar_line_itself_counts(tmp_path: Path) -> None:
    ends = _ends(tmp_path, "G21 G18 G0 X3 Y4\nG17 G1 F100 @10\n")
    assert ends[-1] == pytest.approx((6.0, 8.0, 0.0))
