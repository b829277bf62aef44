"""Tools in the interpreter: T checked against the table, G43 H / G43.1 Z / G49 on Z, and M6
as a manual change (spindle off, change position, a pause), with LinuxCNC's offset rules."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of

from controller.blocks import AuxBlock, LineBlock, StopBlock, StopKind
from controller.errors import NcError
from controller.interpreter.program import read_program
from controller.offsets import ProgramOffsets
from controller.operator.check_cmd import check_program
from controller.tools import Tool, ToolTable

TABLE = ToolTable((Tool(1, 1, 10.5, 6.0, "end mill"), Tool(2, 2, -3.0, 3.0, "drill")))
MILL = replace(XYZ_MILL, tools=replace(XYZ_MILL.tools, table=TABLE,
                                       change_position_mm=(0.0, 0.0, 50.0)))


def ends(blocks: list) -> list[tuple[float, float, float]]:
    return [b.end for b in blocks if isinstance(b, LineBlock)]


def test_g43_offsets_z_by_the_tool_length_until_g49(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G0 Z5\nG43 H1\nG0 Z0\nG0 X1\nG49\nG0 Z0\nG43.1 Z2\nG0 Z1\n"
                            "G91 G43 H2\nG0 Z1\n", MILL)
    # G43 alone does not move; the next Z word goes to program Z + length (LinuxCNC)
    assert ends(b) == [(0, 0, 5), (0, 0, 10.5), (1, 0, 10.5), (1, 0, 0), (1, 0, 3),
                       (1, 0, 4)]  # G91: an increment, whatever the length


def test_g92_and_g10_l20_read_the_position_with_the_length(tmp_path: Path) -> None:
    track = ProgramOffsets()
    path = tmp_path / "p.nc"
    path.write_text("G0 Z20\nG43 H1\nG92 Z0\nG0 Z5\nG92.1\nG10 L20 P1 Z0\n")
    list(read_program(str(path), MILL, track=track))
    assert track.table.g92_mm == (0.0, 0.0, 0.0)
    assert track.table.systems_mm[0][2] == pytest.approx(20 + 5 - 10.5)
    blocks = list(read_program(str(path), MILL))
    assert ends(blocks)[-1] == (0, 0, 25.0)  # G92 Z0 at machine 20 with 10.5: Z5 is 25


def test_m6_stops_the_spindle_goes_to_the_change_position_and_pauses(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "G0 X10 Y10 Z5\nM3 S1000\nT1 M6\nG43\nG0 Z0\n", MILL)
    kinds = [(type(x).__name__, getattr(x, "code", getattr(x, "kind", None))) for x in b]
    assert kinds == [("LineBlock", None), ("OutputBlock", None), ("OutputBlock", None),
                     ("AuxBlock", "M6"), ("LineBlock", None), ("LineBlock", None),
                     ("StopBlock", StopKind.PAUSE), ("LineBlock", None)]
    assert [(c.name, c.value) for c in b[2].changes] == [("spindle", "off")]
    assert [x.end for x in b[4:6]] == [(10, 10, 50), (0, 0, 50)]  # Z up first, then X Y
    assert all(x.rapid for x in b[4:6]) and b[6].position == (0, 0, 50)
    assert b[3].tool == 1 and b[-1].end == (0, 0, 10.5) and b[-1].source.first_line == 5


def test_while_g43_follows_the_loaded_tool_m6_puts_the_new_length_in(tmp_path: Path) -> None:
    track = ProgramOffsets()
    path = tmp_path / "p.nc"
    path.write_text("T1 M6 G43\nG0 Z0\nT2 M6\nG0 Z0\nG43 H1\nT2 M6\nG0 Z1\n")
    b = list(read_program(str(path), MILL, track=track))
    assert [e[2] for e in ends(b) if e[:2] == (0, 0) and e[2] != 50] == [10.5, -3.0, 11.5]
    assert [(e["line"], e["tool"], e["length_mm"], e["table_length_mm"])
            for e in track.io_events] == [(1, 1, 10.5, 10.5), (3, 2, -3.0, -3.0),
                                          (6, 2, 10.5, -3.0)]
    assert all(e["event"] == "tool" and e["t_s"] is None for e in track.io_events)


@pytest.mark.parametrize(("text", "line", "word", "says"), [
    ("G0 X1\nT7\n", 2, "T", "T7 is not in the tool table"),
    ("G43 H9\n", 1, "H", "T9 is not in the tool table"),
    ("G43 H1.5\n", 1, "H", "non-negative tool number"),
    ("G43.1\n", 1, "G43.1", "needs Z"),
    ("G43.1 Z1 G1 X1 F100\n", 1, "G43.1", "both use axis words"),
])
def test_tool_errors_name_the_line_and_word(tmp_path: Path, text: str, line: int, word: str,
                                            says: str) -> None:
    with pytest.raises(NcError) as err:
        blocks_of(tmp_path, text, MILL)
    assert err.value.line == line and err.value.word.startswith(word)
    assert says in err.value.message


def test_a_length_on_a_machine_without_z_is_an_error_naming_the_line(tmp_path: Path) -> None:
    table = replace(XY_TABLE, tools=replace(XY_TABLE.tools, table=TABLE))
    assert blocks_of(tmp_path, "G43 H0\nG49\nT1 M6\nG0 X1\n", table)  # zero lengths are fine
    with pytest.raises(NcError) as err:
        blocks_of(tmp_path, "G0 X1\nT1 M6\nG43\n", table)
    assert err.value.line == 3 and "without a Z axis" in err.value.message


def test_without_a_table_t_words_pass_and_lengths_are_zero(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "T42 M6\nG43 H42\nG0 Z1\n", XYZ_MILL)
    assert ends(b) == [(0, 0, 1)] and isinstance(b[1], StopBlock)
    assert isinstance(b[0], AuxBlock) and b[0].tool == 42


def test_check_refuses_a_length_that_carries_z_out_of_travel(tmp_path: Path) -> None:
    long_tool = replace(MILL, tools=replace(MILL.tools, table=ToolTable((Tool(1, 1, 95.0),))))
    path = tmp_path / "p.nc"
    path.write_text("T1 M6 G43\nG0 Z10\nM2\n")
    with pytest.raises(NcError) as err:
        check_program(str(path), long_tool)
    assert err.value.line == 2 and "Z travel limit exceeded" in err.value.message
    path.write_text("T1 M6 G43\nG0 Z-10\nM2\n")
    assert check_program(str(path), long_tool).path_length_mm > 0
