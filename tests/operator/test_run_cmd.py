"""`cncctl run`: rejection before motion (exit 2), JSON lines and the final summary (exit 0)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller.operator.cli import main

FIELDS = {"motion_time_s", "contour_error_um", "following_error_um_max", "underruns",
          "late_cycles", "min_fifo_ms", "pulses", "final_position_mm"}


def test_bad_program_is_rejected_with_its_location_and_no_motion(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "bad.nc"
    prog.write_text("G21 G90 F600\nG1 X5 Y0\nG1 X\n")
    assert main(["run", str(prog), "--json", "--virtual-time"]) == 2
    out, err = capsys.readouterr()
    assert err.startswith(f"{prog}:3:") and ": error: " in err
    assert out == ""  # not even a start event: nothing moved


def test_json_run_ends_with_the_done_summary(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "l.nc"
    prog.write_text("G21 G90 F1200\nG1 X3 Y1\nG1 X0 Y0\nM2\n")
    assert main(["run", str(prog), "--json", "--virtual-time"]) == 0
    events = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert events[0]["event"] == "start" and events[-1]["event"] == "done"
    final = events[-1]
    assert FIELDS <= set(final)
    assert final["final_position_mm"] == {"x": 0.0, "y": 0.0} and final["underruns"] == 0
    assert all(p["commanded"] == p["executed"] for p in final["pulses"].values())
    assert set(final["contour_error_um"]) == {"max", "rms", "mean"}


def test_a_drive_that_cannot_be_built_is_rejected_before_motion(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "l.nc"
    prog.write_text("G21 G90 F1200\nG1 X3 Y1\nM2\n")
    assert main(["run", str(prog), "--virtual-time", "--drive-option", "fifo=3"]) == 2
    err = capsys.readouterr().err
    assert "unknown drive option 'fifo'" in err and "nothing moved" in err
