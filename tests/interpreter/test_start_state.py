"""The dialect's start state (config `gcode`): grbl's power-up G0 and a default feed before F."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import LINUXCNC_START, mill_with_gcode

from controller.blocks import ArcBlock, HelixBlock, LineBlock
from controller.errors import ConfigError, NcError
from controller.interpreter.program import read_program
from controller.offsets import ProgramOffsets


def run(tmp_path: Path, text: str, gcode: object) -> tuple[list, list[str]]:
    """The motion blocks of `text` on xyz_mill with `gcode`, and the warnings."""
    prog = tmp_path / "prog.nc"
    prog.write_text(text)
    track = ProgramOffsets()
    blocks = list(read_program(str(prog), mill_with_gcode(tmp_path, gcode), track=track))
    moves = [b for b in blocks if isinstance(b, LineBlock | ArcBlock | HelixBlock)]
    return moves, track.warnings


def test_linuxcnc_start_refuses_an_axis_word_before_a_motion_code(tmp_path: Path) -> None:
    with pytest.raises(NcError, match="Z word with no motion mode") as info:
        run(tmp_path, "G21 G90\nZ10\nM2\n", LINUXCNC_START)
    assert info.value.line == 2


def test_power_up_g0_moves_at_rapid_and_says_so_once(tmp_path: Path) -> None:
    moves, warnings = run(tmp_path, "G21 G90\nZ10\nX5\nG1 X6 F100\nM2\n",
                          {"power_up_motion": "G0"})
    assert [(b.rapid, b.end) for b in moves] == [
        (True, (0.0, 0.0, 10.0)), (True, (5.0, 0.0, 10.0)), (False, (6.0, 0.0, 10.0))]
    assert len(warnings) == 1
    assert warnings[0].endswith("prog.nc:2: Z: no motion mode programmed yet: moves at rapid, "
                                "as G0 (gcode.power_up_motion: G0, grbl's power-up mode; "
                                "LinuxCNC refuses)")


@pytest.mark.parametrize("cancel", ["G80", "G1 X1 F100\nG80"])
def test_power_up_g0_is_only_the_start_state_g80_still_cancels(tmp_path: Path,
                                                               cancel: str) -> None:
    with pytest.raises(NcError, match="X word with no motion mode") as info:
        run(tmp_path, f"G21\n{cancel}\nX3\nM2\n", {"power_up_motion": "G0"})
    assert info.value.line == 2 + cancel.count("\n") + 1


def test_no_default_feed_refuses_a_feed_move_before_f(tmp_path: Path) -> None:
    with pytest.raises(NcError, match="G2 feed move with no feed rate: program F first"):
        run(tmp_path, "G21\nG2 X2 I1\nM2\n", LINUXCNC_START)


def test_a_default_feed_moves_until_the_first_f_and_says_so_once(tmp_path: Path) -> None:
    moves, warnings = run(tmp_path, "G21\nG1 X1\nG2 X3 I1\nG1 X4 F60\nX5\nM2\n",
                          {"default_feed_mm_min": 240})
    assert [b.feed_mm_s for b in moves] == [4.0, 4.0, 1.0, 1.0]
    assert len(warnings) == 1
    assert warnings[0].endswith("prog.nc:2: G1: no F programmed yet: moves at "
                                "gcode.default_feed_mm_min = 240 mm/min (Klipper's and "
                                "Marlin's rule; LinuxCNC and grbl refuse)")


def test_a_probe_needs_its_own_f_even_with_a_default_feed(tmp_path: Path) -> None:
    with pytest.raises(NcError, match="G38.2 probe move with no feed rate"):
        run(tmp_path, "G21\nG38.2 Z-5\nM2\n", {"default_feed_mm_min": 240})


@pytest.mark.parametrize(
    ("gcode", "message"),
    [
        ({"default_feed_mm_min": 0}, "gcode.default_feed_mm_min: must be > 0.0"),
        ({"default_feed_mm_min": "fast"}, "gcode.default_feed_mm_min: must be a number"),
        ({"power_up_motion": "G1"}, "gcode.power_up_motion: must be one of none, G0"),
        ({"power_up_motion": True}, "gcode.power_up_motion: must be a string"),
    ],
)
def test_the_start_state_keys_are_read_strictly(tmp_path: Path, gcode: object,
                                                message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        mill_with_gcode(tmp_path, gcode)
