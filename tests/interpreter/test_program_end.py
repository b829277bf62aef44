"""Percent lines and the end of a program, with the warnings for what LinuxCNC refuses."""

from __future__ import annotations

from pathlib import Path

from nc_helpers import XY_TABLE

from controller.interpreter.program import read_program
from controller.offsets import ProgramOffsets


def read(tmp_path: Path, text: str) -> tuple[list, list[str]]:
    path = tmp_path / "p.ngc"
    path.write_text(text)
    track = ProgramOffsets()
    blocks = list(read_program(str(path), XY_TABLE, track=track))
    return blocks, track.warnings


def test_percent_delimited_program_has_no_warning(tmp_path: Path) -> None:
    blocks, warnings = read(tmp_path, "%\nG0 X1\n%\nG0 X99\n")
    assert [b.end[0] for b in blocks] == [1.0] and warnings == []


def test_percent_after_code_ends_with_a_warning(tmp_path: Path) -> None:
    blocks, warnings = read(tmp_path, "G0 X1\n%\nG0 X99\n")
    assert [b.end[0] for b in blocks] == [1.0]
    assert warnings == ["line 2: a % line that no % on the first line opened: the program "
                        "ends here (LinuxCNC refuses it)"]


def test_missing_m2_is_a_warning_and_m2_is_not(tmp_path: Path) -> None:
    _, warnings = read(tmp_path, "G0 X1\nG0 X2\n")
    assert warnings == ["line 2: the program ends without M2, M30 or a closing %: read to "
                        "the end of the file (LinuxCNC refuses it)"]
    _, warnings = read(tmp_path, "G0 X1\nM2\nG0 X5\n")
    assert warnings == []


def test_percent_line_text_after_the_sign_is_not_read(tmp_path: Path) -> None:
    blocks, warnings = read(tmp_path, "% program 12\nG0 X1\n%(end)\n")
    assert [b.end[0] for b in blocks] == [1.0] and warnings == []


def test_cncctl_check_reports_the_warnings(tmp_path: Path) -> None:
    """From outside: `cncctl check` prints them, and --json carries them."""
    import json
    import subprocess
    import sys

    path = tmp_path / "p.ngc"
    path.write_text("G21 F100\no1 repeat [2]\nG1 X1\nG1 X2\no1 endrepeat\n")
    cli = [sys.executable, "-m", "controller.operator.cli", "check", str(path)]
    text = subprocess.run(cli, capture_output=True, text=True, timeout=120, check=True).stdout
    assert "warning: line 5: the program ends without M2, M30 or a closing %" in text
    out = subprocess.run([*cli, "--json"], capture_output=True, text=True, timeout=120,
                         check=True).stdout
    summary = json.loads(out)
    assert summary["ok"] and summary["blocks"]["LineBlock"] == 4
    assert len(summary["warnings"]) == 1 and "LinuxCNC refuses it" in summary["warnings"][0]
