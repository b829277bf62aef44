"""`cncctl` with servo pre-compensation, as a real process: the plan and the run keep the path."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-m", "controller.operator.cli"]
LIMIT_UM = 30.0


def cncctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], cwd=REPO, capture_output=True, text=True, timeout=300)


def test_simulate_reports_the_compensated_plan_within_the_limit_and_faster() -> None:
    prog = str(REPO / "nc_programs" / "naca2415_loop.nc")
    on = cncctl("simulate", prog, "--config", "xy_table", "--json")
    off = cncctl("simulate", prog, "--config", "xy_table_paper", "--json")
    assert on.returncode == 0 and off.returncode == 0, on.stderr + off.stderr
    a, b = json.loads(on.stdout), json.loads(off.stdout)
    assert a["contour_limit_met"] and a["contour_error_true_um"]["max"] <= LIMIT_UM
    assert a["motion_time_s"] < b["motion_time_s"]


def test_run_through_the_processes_measures_the_tool_on_the_path() -> None:
    prog = str(REPO / "nc_programs" / "butterfly.nc")
    out = cncctl("run", prog, "--config", "xy_table", "--virtual-time", "--json")
    assert out.returncode == 0, out.stderr
    final = json.loads(out.stdout.splitlines()[-1])
    assert final["event"] == "done" and final["underruns"] == 0
    assert final["contour_error_um"]["max"] <= LIMIT_UM
    plain = cncctl("run", prog, "--config", "xy_table_paper", "--virtual-time", "--json")
    assert final["final_position_mm"] == json.loads(plain.stdout.splitlines()[-1])[
        "final_position_mm"]  # the same end point, to the pulse
    assert all(p["commanded"] == p["executed"] for p in final["pulses"].values())
