"""G38 in an embedded `cncctl run` on the sim card (a real process) against its simulated
workpiece (drive option probe_workpiece_mm): the trip, the stop along the path after it, the
rest of the program from where the machine stopped, #5063, and LinuxCNC's errors."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from daemon_helpers import CNCCTL, REPO, running_cncd

from controller.probe import Workpiece, trip_point

MILL = str(REPO / "config" / "xyz_mill.yaml")
WORK = "probe_workpiece_mm=-20,-20,-50,20,20,0"  # its top face at Z0
FEED_MM_S = 5.0  # F300
AMAX_MM_S2 = 2450.0  # xyz_mill


def run(tmp_path: Path, text: str, *extra: str) -> tuple[int, list[dict], str]:
    program = tmp_path / "probe.nc"
    program.write_text(text)
    done = subprocess.run([*CNCCTL, "run", str(program), "--json", "--virtual-time",
                           "--config", MILL, *extra], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    events = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    events = [e for e in events if e["event"] != "progress"]
    said = done.stderr + "".join(e.get("message", "") for e in events)  # --json: in the result
    return done.returncode, events, said


def test_g38_2_trips_on_the_face_stops_and_the_program_goes_on_from_there(
        tmp_path: Path) -> None:
    code, events, err = run(tmp_path, "G21 G90 F300\nG0 X5 Y5 Z10\nG38.2 Z-10\n"
                                      "G91 G0 Z2\nG90 G0 X0 Y0\nG0 Z#5063\nM2\n",
                            "--drive-option", WORK)
    assert code == 0, err
    (probe,) = [e for e in events if e["event"] == "probe"]
    assert probe["line"] == 3 and probe["code"] == "G38.2" and probe["tripped"]
    trip_z, stop_z = probe["trip_mm"][2], probe["stop_mm"][2]
    face = trip_point(Workpiece((-20, -20, -50), (20, 20, 0)), (5, 5, 10), (5, 5, -10), True)
    assert face == (5, 5, 0)
    # seen within a motion cycle (2 ms, 10 um at F300) and the servo's lag of the face
    assert -0.05 < trip_z - face[2] <= 0.0
    # the stop starts a few frames after the trip, not behind the card's 100 ms FIFO (0.5 mm)
    overtravel_mm = trip_z - stop_z
    assert 0.0 <= overtravel_mm < 0.1 + 2 * FEED_MM_S**2 / (2 * AMAX_MM_S2)
    final = events[-1]
    assert final["event"] == "done"
    # G91 Z2 from the stop point, then G0 Z#5063: the trip point, as the program reads it
    assert final["final_position_mm"]["z"] == pytest.approx(trip_z, abs=0.0011)
    assert final["final_position_mm"]["x"] == 0.0


def test_a_probe_in_a_loop_runs_once_a_pass_from_where_the_last_one_stopped(
        tmp_path: Path) -> None:
    """pcb2gcode's autoleveller probes a grid from one probe line in a loop (or a numbered
    program called again): each pass is a probe of its own, the next pass from its stop."""
    code, events, err = run(tmp_path, "G21 G90 F300\nG0 X-10 Y5 Z3\n#1 = 0\n"
                                      "o1 while [#1 LT 3]\nG38.2 Z-5\n#[100 + #1] = #5063\n"
                                      "G91 G0 Z3 X5\nG90\n#1 = [#1 + 1]\no1 endwhile\n"
                                      "G0 Z#101\nM2\n", "--drive-option", WORK)
    assert code == 0, err
    probes = [e for e in events if e["event"] == "probe"]
    assert [p["line"] for p in probes] == [5, 5, 5] and all(p["tripped"] for p in probes)
    assert [round(p["trip_mm"][0], 3) for p in probes] == [-10.0, -5.0, 0.0]
    assert all(-0.05 < p["trip_mm"][2] <= 0.0 for p in probes)
    final = events[-1]
    assert final["event"] == "done" and final["final_position_mm"]["x"] == 5.0
    # #101: the second pass's trip, as the program read it
    assert final["final_position_mm"]["z"] == pytest.approx(probes[1]["trip_mm"][2], abs=0.0011)


def test_g38_2_without_contact_is_an_error_g38_3_goes_on(tmp_path: Path) -> None:
    text = "G21 G90 F300\nG0 X50 Y50 Z10\n{}\nG0 Z20\nM2\n"
    code, events, err = run(tmp_path, text.format("G38.2 Z-5"), "--drive-option", WORK)
    assert code == 4 and "line 3: G38.2: the probe move ended without making contact" in err
    assert [e["tripped"] for e in events if e["event"] == "probe"] == [False]
    code, events, err = run(tmp_path, text.format("G38.3 Z-5"), "--drive-option", WORK)
    assert code == 0, err
    assert events[-1]["final_position_mm"]["z"] == 20.0


def test_a_probe_already_in_contact_is_refused_at_its_start(tmp_path: Path) -> None:
    code, events, err = run(tmp_path, "G21 G90 F300\nG0 X5 Y5 Z-1\nG38.2 Z-5\nM2\n",
                            "--drive-option", WORK)
    assert code == 4 and "line 3: G38.2: the probe is already in contact" in err
    # G38.4 away from the work from inside it: contact lost at the face
    code, events, err = run(tmp_path, "G21 G90 F300\nG0 X5 Y5 Z-1\nG38.4 Z5\nG0 Z10\nM2\n",
                            "--drive-option", WORK)
    assert code == 0, err
    (probe,) = [e for e in events if e["event"] == "probe"]
    assert probe["tripped"] and 0.0 <= probe["trip_mm"][2] < 0.05


def test_a_drive_without_a_probe_input_refuses_before_any_motion(tmp_path: Path) -> None:
    code, events, err = run(tmp_path, "G0 X5\nF300\nG38.2 Z-5\nM2\n")
    assert code == 2 and ":3:1: error: G38.2: probing is checked" in err
    assert "has no probe input" in err and not [e for e in events if e["event"] == "done"]
    program = tmp_path / "probe.nc"
    with running_cncd(tmp_path, "--config", MILL) as d:
        d.cncctl("reset")
        done = subprocess.run([*CNCCTL, "run", str(program), "--socket", d.socket_path],
                              capture_output=True, text=True, timeout=60,
                              stdin=subprocess.DEVNULL)
        assert done.returncode == 2 and "the sim drive has no probe input" in done.stderr
        assert d.status()["position_mm"] == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_a_probe_through_cncd(tmp_path: Path) -> None:
    config = tmp_path / "mill_probe.yaml"
    config.write_text(Path(MILL).read_text().replace(
        "drive:\n  backend: sim\n",
        'drive:\n  backend: sim\n  options: {probe_workpiece_mm: "-20,-20,-50,20,20,0"}\n'))
    program = tmp_path / "probe.nc"
    program.write_text("G21 G90 F600\nG0 X5 Y5 Z3\nG38.2 Z-3\nG91 G0 Z1\nG90 G0 Z#5063\n"
                       "M2\n")
    with running_cncd(tmp_path, "--config", str(config)) as d:
        d.cncctl("reset")
        done = subprocess.run([*CNCCTL, "run", str(program), "--json", "--socket",
                               d.socket_path], capture_output=True, text=True, timeout=60,
                              stdin=subprocess.DEVNULL)
        events = [json.loads(line) for line in done.stdout.splitlines()]
        assert done.returncode == 0, done.stderr
        (probe,) = [e for e in events if e["event"] == "probe"]
        assert probe["line"] == 3 and probe["tripped"] and -0.05 < probe["trip_mm"][2] <= 0
        final = events[-1]
        assert final["event"] == "done"
        assert final["final_position_mm"]["z"] == pytest.approx(probe["trip_mm"][2], abs=0.0011)
        status = d.status()
        assert status["state"] == "IDLE" and status["last_probe"] == probe

