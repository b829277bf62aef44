"""plant_<axis> on the sim card and on both simulated peers, from outside: `cncctl run` and
`cncctl simdrive` in their own processes, a slower X loop seen in the run's following error."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from daemon_helpers import LOADED_LINK
from homing_helpers import peer

from controller.config import load_config
from controller.servo.model import mismatched
from controller.servo.plant_option import plant_text

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-m", "controller.operator.cli"]
PROGRAM = "G21 G90 F2400\nG1 X20 Y5\nG1 X0 Y0\nM2\n"
# X's loop 30 % slower than the model (Table II) the controller plans with: its lag is 1/0.7
# of the model's, and the planner does not know it.
SLOW_X = plant_text(mismatched(load_config("xy_table").axis("x").servo, -30.0))
DRIVE_KEY = {"serial": "port", "canopen": "channel"}
EXTRA = LOADED_LINK  # the subject here is the I/O, not the link


@pytest.fixture
def program(tmp_path: Path) -> Path:
    path = tmp_path / "l.nc"
    path.write_text(PROGRAM)
    return path


def run(program: Path, *args: str) -> tuple[int, dict[str, Any], str]:
    """`cncctl run PROGRAM --json ARGS`: (exit code, last JSON event or {}, stderr)."""
    out = subprocess.run([*CLI, "run", str(program), "--json", *args], capture_output=True,
                         text=True, timeout=60, cwd=REPO)
    events = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    return out.returncode, events[-1] if events else {}, out.stderr


def test_a_slower_x_plant_on_the_sim_card_lags_more(program: Path) -> None:
    code, nominal, err = run(program, "--virtual-time")
    assert code == 0 and nominal["event"] == "done", err
    code, slow, err = run(program, "--virtual-time", "--drive-option", f"plant_x={SLOW_X}")
    assert code == 0 and slow["event"] == "done", err
    assert slow["following_error_um_max"] > 1.3 * nominal["following_error_um_max"]
    assert slow["contour_error_um"]["max"] > 2 * nominal["contour_error_um"]["max"]
    assert slow["final_position_mm"] == nominal["final_position_mm"]
    # The percentages apply on top of a given plant: the model given as plant_x, then 30 %
    # slower, is the same machine as SLOW_X given outright.
    model_x = plant_text(load_config("xy_table").axis("x").servo)
    code, on_top, err = run(program, "--virtual-time", "--drive-option", f"plant_x={model_x}",
                            "--drive-option", "plant_pole_pct=-30")
    assert code == 0, err
    assert on_top["following_error_um_max"] == pytest.approx(
        slow["following_error_um_max"], abs=1.0)


@pytest.mark.parametrize("option, named", [("plant_x=1,2,3", "plant_x: expected eight numbers"),
                                           ("plant_y=1,1,1,1,1,1,0,0", "plant_y: unstable"),
                                           (f"plant_z={SLOW_X}", "plant_z: the machine has no Z")])
def test_a_bad_plant_on_the_sim_card_is_refused_before_motion(program: Path, option: str,
                                                              named: str) -> None:
    code, last, err = run(program, "--virtual-time", "--drive-option", option)
    assert code == 2 and named in err and "nothing moved" in err, err
    assert last["event"] == "start" and "Traceback" not in err  # refused before any motion


@pytest.mark.parametrize("backend", ["serial", "canopen"])
def test_each_peer_runs_its_own_plant(program: Path, backend: str) -> None:
    figures = []
    for options in ((), (f"plant_x={SLOW_X}",)):
        with peer(backend, None, *options) as (_, path):
            code, final, err = run(program, "--config", backend, "--drive-option",
                                   f"{DRIVE_KEY[backend]}={path}", *EXTRA[backend])
        assert code == 0 and final["event"] == "done", (final, err)
        figures.append(final["following_error_um_max"])
    nominal_um, slow_um = figures
    assert slow_um > 1.3 * nominal_um, figures


@pytest.mark.parametrize("backend", ["serial", "canopen"])
@pytest.mark.parametrize("option, named", [("plant_x=x", "plant_x: expected eight numbers"),
                                           ("plant_x=1,2,3,4,5,6,7,y", "plant_x: b2 = 'y'"),
                                           ("plant_pole_pct=300", "plant_pole_pct: 300 is not")])
def test_a_bad_plant_on_a_peer_is_refused_with_exit_2(backend: str, option: str,
                                                      named: str) -> None:
    out = subprocess.run([*CLI, "simdrive", backend, "--option", option], capture_output=True,
                         text=True, timeout=30, cwd=REPO)
    assert out.returncode == 2 and named in out.stderr, out
    assert out.stdout == "" and "Traceback" not in out.stderr  # no device was announced


def test_any_bad_peer_option_is_refused_with_exit_2_before_a_device_is_printed() -> None:
    """An unknown option exited 3 (a fault) although nothing had been served."""
    import subprocess
    import sys

    for backend, option in (("serial", "bogus=1"), ("canopen", "heartbeat_ms=-5")):
        done = subprocess.run([sys.executable, "-m", "controller.operator.cli", "simdrive",
                               backend, "--option", option], capture_output=True, text=True,
                              timeout=60)
        assert done.returncode == 2, (backend, done.returncode, done.stderr)
        assert done.stdout == "" and option.split("=")[0] in done.stderr
