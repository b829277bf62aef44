"""Subroutines in other files: `o<name> call` runs `o<name> sub` of `name.ngc` in the
program's folder when the program has none; errors and blocks name that file and its lines."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import XYZ_MILL, mill_with_gcode

from controller.blocks import LineBlock
from controller.errors import ConfigError, NcError
from controller.interpreter.program import position_at_line, read_program
from controller.offsets import ProgramOffsets

SIDE = "(a subroutine file)\no<side> sub\nG1 X#1 Y#2\no<side> endsub\nM2\n"


def write(folder: Path, name: str, text: str) -> str:
    path = folder / name
    path.write_text(text)
    return str(path)


def test_a_call_runs_the_subroutine_of_the_file_named_by_it(tmp_path: Path) -> None:
    write(tmp_path, "side.ngc", SIDE)
    main = write(
        tmp_path, "main.ngc", "G21 F100\no<side> call [5] [2]\nG1 X1\no<SIDE> call [7]\nM2\n"
    )
    moves = [b for b in read_program(main, XYZ_MILL) if isinstance(b, LineBlock)]
    assert [(b.end[0], b.end[1]) for b in moves] == [(5.0, 2.0), (1.0, 2.0), (7.0, 0.0)]
    # each block names the file and line it comes from
    assert [(Path(b.source.path).name, b.source.first_line) for b in moves] == [
        ("side.ngc", 3),
        ("main.ngc", 3),
        ("side.ngc", 3),
    ]


def test_a_subroutine_in_the_program_comes_first(tmp_path: Path) -> None:
    write(tmp_path, "side.ngc", SIDE)
    main = write(
        tmp_path, "main.ngc", "G21 F100\no<side> sub\nG1 X9\no<side> endsub\no<side> call [5]\nM2\n"
    )
    (move,) = [b for b in read_program(main, XYZ_MILL) if isinstance(b, LineBlock)]
    assert move.end[0] == 9.0


def test_an_error_in_the_file_names_that_file_and_line(tmp_path: Path) -> None:
    sub = write(tmp_path, "bad.ngc", "o<bad> sub\nG1 X#<nope>\no<bad> endsub\n")
    main = write(tmp_path, "main.ngc", "G21 F100\no<bad> call\nM2\n")
    with pytest.raises(NcError) as info:
        list(read_program(main, XYZ_MILL))
    assert (info.value.path, info.value.line) == (sub, 2)


def test_a_warning_in_the_file_names_that_file_and_line(tmp_path: Path) -> None:
    sub = write(tmp_path, "unset.ngc", "o<unset> sub\nG1 X#3000\no<unset> endsub\n")
    main = write(tmp_path, "main.ngc", "G21 F100\nG1 X4\no<unset> call\nM2\n")
    track = ProgramOffsets()
    list(read_program(main, XYZ_MILL, track=track))
    assert track.warnings == [
        f"{sub}:2: #3000: parameter #3000 is not set: read as 0 "
        "(LinuxCNC's rule for a numbered parameter)"
    ]


def test_a_missing_file_or_sub_is_an_error_at_the_call(tmp_path: Path) -> None:
    main = write(tmp_path, "main.ngc", "G21\no<gone> call\nM2\n")
    with pytest.raises(
        NcError,
        match=r"main.ngc:2:1: error: no subroutine O<gone> sub in "
        r"the program nor a file gone.ngc in ",
    ):
        list(read_program(main, XYZ_MILL))
    write(tmp_path, "other.ngc", "o<else> sub\no<else> endsub\n")
    main = write(tmp_path, "main.ngc", "G21\no<other> call\nM2\n")
    with pytest.raises(NcError, match=r"other.ngc has no O<other> sub"):
        list(read_program(main, XYZ_MILL))


def test_run_from_a_line_after_a_call_is_not_started_inside_the_file(tmp_path: Path) -> None:
    write(tmp_path, "side.ngc", SIDE)
    main = write(tmp_path, "main.ngc", "G21 F100\no<side> call [5]\nG1 X1\nG1 X2\nM2\n")
    assert position_at_line(main, XYZ_MILL, 4).position_mm == (1.0, 0.0, 0.0)


def test_the_configured_subroutine_path_is_searched_after_the_program_folder(
    tmp_path: Path,
) -> None:
    lib = tmp_path / "lib"
    lib.mkdir()
    write(lib, "side.ngc", SIDE)
    progs = tmp_path / "progs"
    progs.mkdir()
    main = write(progs, "main.ngc", "G21 F100\no<side> call [3]\nM2\n")
    config = mill_with_gcode(tmp_path, {"subroutine_path": ["lib"]})
    assert config.gcode.subroutine_path == (str(lib),)
    (move,) = [b for b in read_program(main, config) if isinstance(b, LineBlock)]
    assert move.end[0] == 3.0 and move.source.path == str(lib / "side.ngc")
    write(progs, "side.ngc", SIDE.replace("X#1", "X[#1 + 1]"))
    (move,) = [b for b in read_program(main, config) if isinstance(b, LineBlock)]
    assert move.end[0] == 4.0  # the program's own folder first


@pytest.mark.parametrize(
    ("gcode", "message"),
    [
        ({"subroutine_path": ["nowhere"]}, "gcode.subroutine_path: nowhere: no such folder"),
        ({"subroutine_path": "lib"}, "gcode.subroutine_path: must be a list of folder names"),
        ({"sub_path": ["lib"]}, "gcode.sub_path"),
    ],
)
def test_the_gcode_section_is_read_strictly(tmp_path: Path, gcode: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        mill_with_gcode(tmp_path, gcode)


def test_a_name_with_a_folder_is_not_looked_up(tmp_path: Path) -> None:
    (tmp_path / "lib").mkdir()
    write(tmp_path / "lib", "side.ngc", SIDE)
    main = write(tmp_path, "main.ngc", "G21\no<lib/side> call\nM2\n")
    with pytest.raises(NcError, match=r"a file name without folders is looked up"):
        list(read_program(main, XYZ_MILL))
