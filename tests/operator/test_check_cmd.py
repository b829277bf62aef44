"""`cncctl check`: exit codes, the compiler-style error line, the summary and --json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller.blocks import NurbsBlock
from controller.config import load_config
from controller.errors import NcError
from controller.operator import check_cmd
from controller.operator.check_cmd import check_program
from controller.operator.cli import main

REPO = Path(__file__).resolve().parents[2]


def test_good_program_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(REPO / "nc_programs/arcs.nc")]) == 0
    out = capsys.readouterr().out
    assert "OK (config xy_table)" in out and "ArcBlock 5" in out and "X: 0.0000 .. 80.0000" in out


def test_json_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(REPO / "nc_programs/g64_corners.nc"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["ok"] and data["blocks"] == {"LineBlock": 10, "StopBlock": 1}
    assert data["extents_mm"]["x"] == [-40.0, 80.0] and data["travel_mm"]["y"] == [-150, 150]
    corners = [(0, 0), (50, 0), (50, 30), (80, 30), (80, -30), (20, -40), (0, -20), (-40, -20),
               (-40, 20), (-10, 40), (0, 0)]
    length = sum(((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2) ** 0.5
                 for a, b in zip(corners, corners[1:], strict=False))
    assert data["path_length_mm"] == pytest.approx(length)


def test_error_line_on_stderr_and_exit_2(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "bad.nc"
    prog.write_text("G21\nG1 X10\n")
    assert main(["check", str(prog)]) == 2
    err = capsys.readouterr().err
    assert err == f"{prog}:2:1: error: G1 feed move with no feed rate: program F first\n"


def test_json_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "bad.nc"
    prog.write_text("G0 X200\n")
    assert main(["check", str(prog), "--json"]) == 2
    data = json.loads(capsys.readouterr().out)
    assert not data["ok"] and data["error"]["line"] == 1 and data["error"]["word"] == "X"


def test_mill_config_accepts_z(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "z.nc"
    prog.write_text("G0 Z5\nG1 Z-2 F100\n")
    assert main(["check", str(prog)]) == 2
    assert main(["check", str(prog), "--config", "xyz_mill"]) == 0
    assert "Z: -2.0000 .. 5.0000 mm" in capsys.readouterr().out


def test_config_error_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(REPO / "nc_programs/arcs.nc"), "--config", "no_such"]) == 2
    assert "no_such" in capsys.readouterr().err


def test_missing_program_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "/nonexistent.nc"]) == 2
    assert "/nonexistent.nc:0:0: error: cannot open program" in capsys.readouterr().err


def test_check_opens_the_configured_drive_before_any_motion(
        capsys: pytest.CaptureFixture[str]) -> None:
    program = str(REPO / "nc_programs/naca2415.nc")
    assert main(["check", program, "--drive-option", "realtime=false"]) == 0
    capsys.readouterr()
    assert main(["check", program, "--drive-option", "fifo_frame=16"]) == 2
    err = capsys.readouterr().err
    assert "drive 'sim' cannot be opened" in err and "'fifo_frame'" in err
    assert main(["check", program, "--drive-option", "noequals"]) == 2
    assert "expected KEY=VALUE" in capsys.readouterr().err


@pytest.mark.parametrize(("control_x", "inside"), [(190, True), (220, False), (140, True)])
def test_the_check_before_motion_refuses_exactly_the_nurbs_cncctl_check_refuses(
        tmp_path: Path, control_x: int, inside: bool) -> None:
    """Before motion a NURBS inside its control points' box is not sampled (summary=False):
    a curve whose control point leaves the travel but which does not (X190: it reaches 145)
    is still sampled and passes; one that leaves it (X220: 160) is refused with the same
    error as by `cncctl check`."""
    program = tmp_path / "nurbs.nc"
    program.write_text(f"F100\nG0 X100 Y0\nG5.2 P1 L3\nX{control_x} Y10 P1\nX100 Y20 P1\nG5.3\n"
                       "M2\n", encoding="utf-8")
    config = load_config(None)
    errors = []
    for summary in (True, False):
        try:
            result = check_program(str(program), config, summary=summary)
            assert (result is None) == (not summary)
            errors.append(None)
        except NcError as exc:
            errors.append(exc.format())
    assert errors[0] == errors[1]
    assert (errors[0] is None) == inside
    if not inside:
        assert "X travel limit exceeded: the path reaches 160.0000 mm" in errors[0]


def test_the_check_before_motion_samples_no_nurbs_inside_the_travel(
        monkeypatch: pytest.MonkeyPatch) -> None:
    sampled = []
    original = check_cmd._GEOMETRY[NurbsBlock]  # noqa: SLF001
    monkeypatch.setitem(check_cmd._GEOMETRY, NurbsBlock,  # noqa: SLF001
                        lambda block: sampled.append(block) or original(block))
    naca = str(REPO / "nc_programs/naca2415.nc")
    assert check_program(naca, load_config(None), summary=False) is None
    assert sampled == []
    summary = check_program(naca, load_config(None))
    assert len(sampled) == 1 and summary is not None and summary.path_length_mm > 60.0


@pytest.mark.parametrize("command", ["check", "run"])
def test_a_missing_offset_table_is_an_error_not_zero_offsets(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        command: str) -> None:
    missing = tmp_path / "offsets.json"
    monkeypatch.setenv("CNCD_SOCKET", str(tmp_path / "none.sock"))  # no daemon: embedded
    words = [command, str(REPO / "nc_programs/arcs.nc"), "--offsets", str(missing)]
    assert main(words + (["--virtual-time"] if command == "run" else [])) == 2
    assert f"{missing}: no such offset table" in capsys.readouterr().err


def test_json_says_why_when_the_drive_cannot_be_opened(
        capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["check", str(REPO / "nc_programs/naca2415.nc"), "--config", "canopen",
                 "--drive-option", "channel=/dev/cnc-no-such-adapter", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 2 and out["ok"] is False and out["error"]["kind"] == "drive"
    assert "no CAN adapter at /dev/cnc-no-such-adapter" in out["error"]["message"]
