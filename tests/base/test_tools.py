"""The tool table: LinuxCNC's tool.tbl lines read strictly, written back, kept atomically."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from controller.config import load_config
from controller.errors import ConfigError
from controller.tools import (
    Tool,
    ToolTable,
    ToolTableError,
    load_tool_table,
    parse_tool_table,
    save_tool_table,
)

REPO = Path(__file__).resolve().parents[2]
LINUXCNC_SIM_TBL = """T1 P1 D0.125000 Z+0.511000 ;1/8 end mill
T2 P2 D0.062500 Z+0.100000 ;1/16 end mill
T3 P3 D0.201000 Z+1.273000 ;#7 tap drill

; a comment line
"""


def test_a_linuxcnc_table_reads_with_its_comments() -> None:
    table = parse_tool_table(LINUXCNC_SIM_TBL, "tool.tbl")
    assert [t.number for t in table.tools] == [1, 2, 3]
    assert table.get(3) == Tool(3, 3, 1.273, 0.201, "#7 tap drill")
    assert table.length_mm(1) == 0.511 and table.length_mm(0) == 0.0
    with pytest.raises(KeyError):
        table.length_mm(4)


@pytest.mark.parametrize(("text", "line", "says"), [
    ("T1 Z1\nT1 Z2\n", 2, "T1 is already on line 1"),
    ("T1 X3\n", 1, "X word"),
    ("T1 Z1 Z2\n", 1, "two Z words"),
    ("P3 Z1\n", 1, "needs T"),
    ("T1.5\n", 1, "whole number"),
    ("T0 Z1\n", 1, "must be 1.."),
    ("T1 Z5000\n", 1, "within +-1000"),
    ("T1 D-1\n", 1, "diameter"),
    ("T1 Zabc\n", 1, "cannot read"),
])
def test_a_bad_line_is_an_error_naming_the_line(text: str, line: int, says: str) -> None:
    with pytest.raises(ToolTableError) as err:
        parse_tool_table(text, "t.tbl")
    assert err.value.line == line and says in str(err.value)
    assert str(err.value).startswith(f"t.tbl:{line}: ")


tools = st.builds(Tool, st.integers(1, 99999), st.integers(0, 99999),
                  st.floats(-1000, 1000).map(lambda v: round(v, 6)),
                  st.floats(0, 1000).map(lambda v: round(v, 6)),
                  st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")),
                          max_size=20).map(str.strip))


@given(st.lists(tools, max_size=8, unique_by=lambda t: t.number))
def test_a_table_written_reads_back_the_same(listed: list[Tool]) -> None:
    table = ToolTable()
    for tool in listed:
        table = table.with_tool(tool)
    assert parse_tool_table(table.text(), "x") == table


def test_the_file_is_written_atomically_and_read_strictly(tmp_path: Path) -> None:
    path = tmp_path / "tool.tbl"
    assert load_tool_table(path) == ToolTable()
    with pytest.raises(ToolTableError, match="no such tool table"):
        load_tool_table(path, missing_ok=False)
    table = ToolTable().with_tool(Tool(5, 5, 12.5, 6.0, "end mill"))
    save_tool_table(path, table)
    assert path.read_text() == "T5 P5 Z12.5 D6 ;end mill\n"
    assert load_tool_table(path) == table
    assert [p.name for p in tmp_path.iterdir()] == ["tool.tbl"]  # no temporary left
    assert load_tool_table(path).without(5) == ToolTable()
    path.write_bytes(b"T1 Z1\n" * 200_000)
    with pytest.raises(ToolTableError, match="larger than"):
        load_tool_table(path)


def _mill_with(tmp_path: Path, tools_yaml: str) -> Path:
    text = (REPO / "config" / "xyz_mill.yaml").read_text() + tools_yaml
    path = tmp_path / "mill.yaml"
    path.write_text(text)
    return path


def test_the_config_reads_the_tools_section_strictly(tmp_path: Path) -> None:
    (tmp_path / "tool.tbl").write_text("T2 P2 Z-3 D3\n")
    cfg = load_config(str(_mill_with(tmp_path, "tools:\n  change_position_mm: [0, 0, 50]\n"
                                               "  table_file: tool.tbl\n")))
    assert cfg.tools.change_position_mm == (0.0, 0.0, 50.0)
    assert cfg.tools.table is not None and cfg.tools.table.length_mm(2) == -3.0
    assert load_config("xyz_mill").tools.table is None  # no table in force
    for bad, key in (("  change_position_mm: [0, 0, 500]\n", "tools.change_position_mm"),
                     ("  change_position_mm: [0, 0]\n", "tools.change_position_mm"),
                     ("  table_file: missing.tbl\n", "tools.table_file"),
                     ("  tabel_file: tool.tbl\n", "tools.tabel_file")):
        with pytest.raises(ConfigError) as err:
            load_config(str(_mill_with(tmp_path, "tools:\n" + bad)))
        assert err.value.key == key
