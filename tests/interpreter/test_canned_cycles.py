"""Canned cycles (G73 G81 G82 G83 G85 G89, G98/G99, R Q P L) and G28/G30 as LinuxCNC runs them."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import LINUXCNC_START, XY_TABLE, XYZ_MILL, blocks_of, mill_with_gcode

from controller.blocks import DwellBlock, LineBlock, PathMode
from controller.errors import NcError


def moves(tmp_path: Path, text: str) -> list[tuple[str, tuple[float, float, float]]]:
    out = []
    for b in blocks_of(tmp_path, text, XYZ_MILL):
        if isinstance(b, LineBlock):
            out.append(("G0" if b.rapid else "G1", tuple(round(v, 6) for v in b.end)))
        elif isinstance(b, DwellBlock):
            out.append(("G4", (b.seconds, 0.0, 0.0)))
    return out


def test_g81_g98_returns_to_the_start_height(tmp_path: Path) -> None:
    m = moves(tmp_path, "F100\nG0 Z10\nG98 G81 X5 Y6 Z-2 R1\nX8\nG80\nG0 X0\n")
    assert m == [
        ("G0", (0, 0, 10)),
        ("G0", (5, 6, 10)), ("G0", (5, 6, 1)), ("G1", (5, 6, -2)), ("G0", (5, 6, 10)),
        ("G0", (8, 6, 10)), ("G0", (8, 6, 1)), ("G1", (8, 6, -2)), ("G0", (8, 6, 10)),
        ("G0", (0, 6, 10)),
    ]


def test_g99_returns_to_r_and_a_start_below_r_goes_up_first(tmp_path: Path) -> None:
    m = moves(tmp_path, "F100\nG99 G82 X5 Z-2 R3 P0.5\n")
    assert m == [("G0", (0, 0, 3)), ("G0", (5, 0, 3)), ("G1", (5, 0, -2)),
                 ("G4", (0.5, 0, 0)), ("G0", (5, 0, 3))]


def test_g85_and_g89_feed_out(tmp_path: Path) -> None:
    m = moves(tmp_path, "F100\nG0 Z5\nG85 X1 Z-1 R2\nG89 X2 Z-1 R2 P1\n")
    # G85 (LinuxCNC 2.9): feed out to R, then traverse to the clear height
    assert m[1:6] == [("G0", (1, 0, 5)), ("G0", (1, 0, 2)), ("G1", (1, 0, -1)),
                      ("G1", (1, 0, 2)), ("G0", (1, 0, 5))]
    assert m[6:] == [("G0", (2, 0, 5)), ("G0", (2, 0, 2)), ("G1", (2, 0, -1)),
                     ("G4", (1.0, 0, 0)), ("G1", (2, 0, 5))]


def test_g91_repeats_step_in_xy_and_take_r_and_z_incrementally(tmp_path: Path) -> None:
    m = moves(tmp_path, "F100\nG0 Z4\nG91 G81 X2 Y1 Z-3 R-1 L3\n")
    # R = 4 - 1 = 3, bottom = 3 - 3 = 0; retract to the start Z (4, G98 default)
    holes = [(2 * k, k) for k in (1, 2, 3)]
    expected = [("G0", (0, 0, 4))]
    for x, y in holes:
        expected += [("G0", (x, y, 4)), ("G0", (x, y, 3)), ("G1", (x, y, 0)), ("G0", (x, y, 4))]
    assert m == expected


def test_g73_chip_break_and_g83_peck(tmp_path: Path) -> None:
    m73 = moves(tmp_path, "F100\nG0 Z5\nG73 X0 Z-2.5 R1 Q1\n")
    b = 0.254  # LinuxCNC backs off 0.010 in
    assert m73[1:] == [("G0", (0, 0, 1)), ("G1", (0, 0, 0)), ("G0", (0, 0, b)),
                       ("G1", (0, 0, -1)), ("G0", (0, 0, -1 + b)), ("G1", (0, 0, -2)),
                       ("G0", (0, 0, -2 + b)), ("G1", (0, 0, -2.5)), ("G0", (0, 0, 5))]
    m83 = moves(tmp_path, "F100\nG0 Z5\nG83 X0 Z-1.5 R1 Q1\n")
    # G83 (LinuxCNC 2.9): out to R between pecks, to the clear height at the end
    assert m83[1:] == [("G0", (0, 0, 1)), ("G1", (0, 0, 0)), ("G0", (0, 0, 1)),
                       ("G0", (0, 0, b)), ("G1", (0, 0, -1)), ("G0", (0, 0, 1)),
                       ("G0", (0, 0, -1 + b)), ("G1", (0, 0, -1.5)), ("G0", (0, 0, 5))]


@settings(max_examples=60, deadline=None)
@given(r=st.floats(0.5, 5), depth=st.floats(0.1, 20), q=st.floats(0.2, 5),
       start=st.floats(5.5, 30), retract_r=st.booleans())
def test_g83_pecks_stay_in_the_hole_and_end_at_the_clear_plane(
        tmp_path_factory: pytest.TempPathFactory, r: float, depth: float, q: float,
        start: float, retract_r: bool) -> None:
    tmp = tmp_path_factory.mktemp("g83")
    bottom = r - depth
    mode = "G99" if retract_r else "G98"
    text = f"F300\nG0 Z{start:.4f}\n{mode} G83 X3 Y4 Z{bottom:.4f} R{r:.4f} Q{q:.4f}\n"
    m = moves(tmp, text)
    cycle = m[1:]
    r4, b4, q4, s4 = (round(v, 4) for v in (r, bottom, q, start))
    clear = r4 if retract_r else s4
    feeds = [p for kind, p in cycle if kind == "G1"]
    assert all(p[:2] == (3, 4) for _, p in cycle[1:])
    assert all(b4 - 1e-9 <= p[2] <= r4 for p in feeds)  # every feed ends inside the hole
    assert feeds[-1][2] == pytest.approx(b4)
    assert cycle[-1] == ("G0", (3, 4, pytest.approx(clear)))
    # one feed per peck: the depths r-q, r-2q, ... above the bottom, then the bottom
    pecks = 0
    d = r4 - q4
    while d > b4:
        pecks += 1
        d -= q4
    assert len(feeds) == pecks + 1
    assert all(z <= max(s4, r4) + 1e-9 for _, (_, _, z) in cycle)


def test_cycle_words_are_sticky_and_checked(tmp_path: Path) -> None:
    m = moves(tmp_path, "F100\nG0 Z5\nG81 X1 Z-1 R2\nY3\nG80\n")
    assert ("G1", (1, 3, -1)) in m  # Z and R kept from the line before
    for text, fragment in [
        ("F100\nG81 X1 Z-1\n", "G81 needs R"),
        ("F100\nG81 X1 R2\n", "G81 needs Z"),
        ("F100\nG83 X1 Z-1 R2\n", "G83 needs Q"),
        ("F100\nG82 X1 Z-1 R2\n", "G82 needs P"),
        ("F100\nG81 X1 Z3 R2\n", "R plane (2) is below the bottom Z (3)"),
        ("F100\nG81 X1 Z-1 R2 L0\n", "L (repeats) must be a positive integer"),
        ("F100\nG18\nG81 X1 Z-1 R2\n", "XY plane"),  # cycles run in G17 only
    ]:
        with pytest.raises(NcError) as info:
            blocks_of(tmp_path, text, XYZ_MILL)
        assert fragment in info.value.message


def test_a_cycle_before_any_f_is_refused_or_takes_the_default_feed(tmp_path: Path) -> None:
    strict = mill_with_gcode(tmp_path, LINUXCNC_START)
    with pytest.raises(NcError, match="G81 feed move with no feed rate"):
        blocks_of(tmp_path, "G81 X1 Z-1 R2\n", strict)
    feeds = [b.feed_mm_s for b in blocks_of(tmp_path, "G81 X1 Z-1 R2\nG80\n", XYZ_MILL)
             if isinstance(b, LineBlock) and not b.rapid]
    assert feeds == [XYZ_MILL.gcode.default_feed_mm_min / 60.0]


def test_cycle_moves_are_exact_path_and_modes_come_back(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "F100\nG64 P0.05\nG81 X1 Z-1 R2\nG80\nG1 X5\n", XYZ_MILL)
    lines = [blk for blk in b if isinstance(blk, LineBlock)]
    assert all(blk.path.mode == PathMode.EXACT_PATH for blk in lines[:-1])
    assert lines[-1].path.mode == PathMode.BLEND


def test_g0_g80_on_one_line_and_the_safety_line(tmp_path: Path) -> None:
    m = moves(tmp_path, "G00 G17 G40 G49 G80 G90\nG0 G80 X1\nG80 G1 X2 F60\n")
    assert m == [("G0", (1, 0, 0)), ("G1", (2, 0, 0))]
    with pytest.raises(NcError, match="both in the motion modal group"):
        blocks_of(tmp_path, "G0 G1 X1 F10\n", XYZ_MILL)


def test_g28_g30_stored_positions(tmp_path: Path) -> None:
    text = ("G0 X10 Y20 Z5\nG28.1\nG0 X1 Y2 Z3\nG30.1\nG0 X7 Y7 Z7\n"
            "G28 Z9\nG28\nG30\nG91 G28 X1\nG90\n#1 = #5161\nG0 X[#1 + #5182]\n")
    m = moves(tmp_path, text)
    assert m[3:] == [
        ("G0", (7, 7, 9)), ("G0", (7, 7, 5)),  # through Z9, then only Z to its stored 5
        ("G0", (10, 20, 5)),  # G28: every axis
        ("G0", (1, 2, 3)),  # G30
        ("G0", (2, 2, 3)), ("G0", (10, 2, 3)),  # G91 G28 X1: X+1, then X home
        ("G0", (12, 2, 3)),  # #5161 + #5182 = 10 + 2
    ]


def test_g28_without_stored_position_goes_to_machine_zero(tmp_path: Path) -> None:
    (b,) = blocks_of(tmp_path, "G0 X5 Y5\nG28\n")[1:]
    assert b.end == (0.0, 0.0, 0.0)
    with pytest.raises(NcError, match="G28 and G1 both use axis words"):
        blocks_of(tmp_path, "G28 G1 X1 F10\n", XY_TABLE)


def test_g98_retracts_to_the_initial_level_of_the_cycle_run(tmp_path: Path) -> None:
    """LinuxCNC 2.9: G98 goes back to the Z where the first cycle line (since the last other
    motion) started, not to where the line before left the tool."""
    m = moves(tmp_path, "F100\nG0 Z10\nG99 G81 X1 Z-1 R2\nG98 G81 X2 Z-1 R2\nG0 Z3\n"
                        "G98 G81 X3 Z-1 R2\n")
    assert m[4] == ("G0", (1, 0, 2))  # G99: back to R
    # the G98 line starts at R, below its level: over at the level (10), then down to R
    assert m[5:9] == [("G0", (2, 0, 10)), ("G0", (2, 0, 2)), ("G1", (2, 0, -1)),
                      ("G0", (2, 0, 10))]
    assert m[9:] == [("G0", (2, 0, 3)), ("G0", (3, 0, 3)), ("G0", (3, 0, 2)),
                     ("G1", (3, 0, -1)), ("G0", (3, 0, 3))]  # after G0 Z3 the level is 3
