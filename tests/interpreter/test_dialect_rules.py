"""What phcnc accepts beyond LinuxCNC's refusals, each with a warning naming file, line, word
and the rule followed: unset numbered parameters read as 0, S clamped to the spindle's maximum."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import REPO, XYZ_MILL

from controller.blocks import LineBlock, OutputBlock
from controller.errors import NcError
from controller.interpreter.program import read_program
from controller.offsets import ProgramOffsets


def read(tmp_path: Path, text: str) -> tuple[list, list[str], str]:
    path = tmp_path / "p.ngc"
    path.write_text(text)
    track = ProgramOffsets()
    blocks = list(read_program(str(path), XYZ_MILL, track=track))
    return blocks, track.warnings, str(path)


def ends_x(blocks: list) -> list[float]:
    return [b.end[0] for b in blocks if isinstance(b, LineBlock)]


def test_an_unset_numbered_parameter_reads_0_with_a_warning(tmp_path: Path) -> None:
    blocks, warnings, path = read(tmp_path, "G21\n#1 = 4\nG0 X[#1 + #2002] Y#2002\nM2\n")
    assert ends_x(blocks) == [4.0]
    assert blocks[0].end[1] == 0.0
    # one warning for the line, even though #2002 is read twice there
    assert warnings == [
        f"{path}:3: #2002: parameter #2002 is not set: read as 0 (LinuxCNC's "
        "rule for a numbered parameter)"
    ]


def test_a_set_parameter_and_the_g28_position_warn_nothing(tmp_path: Path) -> None:
    blocks, warnings, _ = read(tmp_path, "G21\n#7 = 3\nG0 X#7\nG28\nM2\n")
    assert ends_x(blocks) == [3.0, 0.0] and warnings == []


def test_a_parameter_read_in_a_condition_warns_at_its_o_word_line(tmp_path: Path) -> None:
    text = "G21\no1 if [#30 EQ 0]\nG0 X2\no1 endif\nM2\n"
    blocks, warnings, path = read(tmp_path, text)
    assert ends_x(blocks) == [2.0]
    assert len(warnings) == 1 and warnings[0].startswith(f"{path}:2: #30: ")


def test_a_named_parameter_never_set_is_still_an_error(tmp_path: Path) -> None:
    """LinuxCNC refuses it too ("Named parameter #<depth> not defined")."""
    with pytest.raises(NcError, match=r"named parameter #<depth> is not set"):
        read(tmp_path, "G21\nG0 X#<depth>\nM2\n")


def spindle_rpms(blocks: list) -> list[float]:
    return [
        c.value
        for b in blocks
        if isinstance(b, OutputBlock)
        for c in b.changes
        if c.name == "spindle_rpm"
    ]


def test_s_above_the_spindle_maximum_is_clamped_with_a_warning(tmp_path: Path) -> None:
    top = XYZ_MILL.io.spindle.max_rpm
    text = f"G21\nM3 S{top + 6000:g}\nG0 X1\nS{top / 2:g}\nM2\n"
    blocks, warnings, path = read(tmp_path, text)
    assert spindle_rpms(blocks) == [top, top / 2]
    assert warnings == [
        f"{path}:2: S{top + 6000:g}: above the spindle's {top:g} rpm "
        f"(io.spindle.max_rpm): clamped to {top:g} rpm (grbl's rule: S is "
        "clamped to its maximum)"
    ]


def test_s_at_the_maximum_and_a_surface_speed_are_not_clamped(tmp_path: Path) -> None:
    top = XYZ_MILL.io.spindle.max_rpm
    blocks, warnings, _ = read(tmp_path, f"G21\nM3 S{top:g}\nG96 S{top * 2:g}\nM2\n")
    assert spindle_rpms(blocks) == [top] and warnings == []


def test_pcb2gcode_s30000_runs_at_the_spindle_maximum_with_one_warning() -> None:
    """A CAM program asking for more rpm than xyz_mill's spindle has (pcb2gcode's lift-mill
    test, tests/data/cam/LICENSE-NOTE.md): accepted, clamped, one warning naming line 8."""
    path = REPO / "tests" / "data" / "cam" / "pcb2gcode" / "lift-mill" / "outline.ngc"
    track = ProgramOffsets()
    blocks = list(read_program(str(path), XYZ_MILL, track=track))
    assert set(spindle_rpms(blocks)) == {XYZ_MILL.io.spindle.max_rpm}
    assert [w.split(": ")[1] for w in track.warnings] == ["S30000"]
    assert track.warnings[0].startswith(f"{path}:8: S30000: ")
