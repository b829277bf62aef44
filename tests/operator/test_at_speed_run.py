"""The spindle's at-speed input in a real `cncctl run` process on the sim card (wall-clock
time): a spindle that comes to speed lets the job go on, one that never does ends it in
FAULT naming the input, with the spindle off and the position known."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import yaml
from daemon_helpers import CNCCTL, REPO


def run(tmp_path: Path, spinup: str) -> tuple[int, dict[str, Any]]:
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["io"]["spindle"].update(spin_up_s=0.0, at_speed_input=True, at_speed_timeout_s=0.3)
    config = tmp_path / "mill.yaml"
    config.write_text(yaml.safe_dump(data))
    program = tmp_path / "spin.nc"
    program.write_text("G21 G90\nM3 S1000\nG1 X1 F600\nM2\n")
    done = subprocess.run(
        [
            *CNCCTL,
            "run",
            str(program),
            "--json",
            "--config",
            str(config),
            "--drive-option",
            f"spindle_spinup_s={spinup}",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    return done.returncode, json.loads(done.stdout.splitlines()[-1])


def test_a_spindle_at_speed_within_the_time_out_lets_the_job_go_on(tmp_path: Path) -> None:
    code, final = run(tmp_path, "0.1")
    assert code == 0 and final["event"] == "done", final
    assert final["final_position_mm"]["x"] == 1.0


def test_a_spindle_never_at_speed_faults_naming_the_input(tmp_path: Path) -> None:
    code, final = run(tmp_path, "never")
    assert code != 0 and final["event"] == "fault"
    assert final["message"] == (
        "line 2: spindle not at speed within 0.3 s (input: sim card, "
        "option spindle_spinup_s, io.spindle.at_speed_timeout_s)"
    )
    assert final["outputs"]["spindle"] == "off" and final["position_known"]
    assert final["final_position_mm"] == {"x": 0.0, "y": 0.0, "z": 0.0}
