"""Work offsets kept by cncd across restarts, and run from line after a fault, from outside."""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

from daemon_helpers import CNCCTL, REPO, running_cncd, start_run, wait_moving

SQUARE = "G21 G90 G64 F1500\nG0 X0 Y0\nG1 X30\nG1 Y10\nG1 X0\nG1 Y0\nM2\n"


def test_offsets_set_here_select_and_kept_across_a_restart(tmp_path: Path) -> None:
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G1 X1 Y2 F1200\nM2\n")
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        assert d.cncctl("offset", "set", "G55", "X10", "Y5").returncode == 0
        assert d.cncctl("offset", "set", "G56", "Q1").returncode == 2  # bad word
        nothing = d.cncctl("offset", "set", "G56")  # neither values nor --here: not a no-op
        assert nothing.returncode == 2 and "set needs values" in nothing.stderr
        no_z = d.cncctl("offset", "set", "G56", "Z5")  # xy_table has no Z
        assert no_z.returncode == 2 and "no axis Z" in no_z.stderr
        assert d.cncctl("offset", "select", "G55").returncode == 0
        assert d.status()["offsets"]["active"] == "G55"
    with running_cncd(tmp_path) as d:  # same state directory: a restarted daemon
        d.cncctl("reset")
        status = d.status()
        assert status["offsets"]["active"] == "G55"
        assert status["offsets"]["systems_mm"]["G55"] == {"x": 10.0, "y": 5.0, "z": 0.0}
        assert status["work_position_mm"] == {"x": -10.0, "y": -5.0}
        ran = d.cncctl("run", str(program), "--json")
        final = json.loads(ran.stdout.splitlines()[-1])
        assert ran.returncode == 0 and final["final_position_mm"] == {"x": 11.0, "y": 7.0}
        # M2 selects G54 again (LinuxCNC): the table the program leaves is kept.
        status = d.status()
        assert status["line"] is None and status["last_job"]["last_line"] == 1  # no job now
        assert status["offsets"]["active"] == "G54"
        assert status["work_position_mm"] == {"x": 11.0, "y": 7.0}
        # --here: the current position becomes G54's zero; the program then starts here.
        assert d.cncctl("offset", "set", "G54", "--here").returncode == 0
        assert d.status()["work_position_mm"] == {"x": 0.0, "y": 0.0}
        far = tmp_path / "far.nc"
        far.write_text("G21 G90 G1 X145 F1200\nM2\n")  # 145 + 11 > 150: out of travel
        refused = d.cncctl("run", str(far), "--json")
        assert refused.returncode == 2 and "machine coordinates" in refused.stderr


def test_check_uses_an_offset_table_file(tmp_path: Path) -> None:
    table = tmp_path / "offsets.json"
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        d.cncctl("offset", "set", "G54", "X100")
        table.write_bytes((d.state_dir / "offsets.json").read_bytes())
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G1 X60 F600\nM2\n")
    ok = subprocess.run([*CNCCTL, "check", str(program)], capture_output=True, text=True)
    bad = subprocess.run([*CNCCTL, "check", str(program), "--offsets", str(table)],
                         capture_output=True, text=True)
    assert ok.returncode == 0
    assert bad.returncode == 2 and "160.0000 mm in machine coordinates" in bad.stderr


def test_run_from_line_after_a_fault_finishes_the_part(tmp_path: Path) -> None:
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, program)
        try:
            wait_moving(run, after_s=1.2)  # on the second side or so
            assert d.cncctl("estop").returncode == 0  # the injected fault
            run.communicate(timeout=20)
        finally:
            run.kill()
        status = d.status()
        last = status["last_job"]
        assert status["state"] == "ESTOP" and last["last_line"] >= 3
        stopped = status["position_mm"]
        d.cncctl("reset")
        line = last["last_line"]  # the line that was running: start it again
        again = d.cncctl("run", str(program), "--json", "--from-line", str(line), "--yes")
        events = [json.loads(x) for x in again.stdout.splitlines()]
        assert again.returncode == 0, again.stderr
        final = events[-1]
        assert final["event"] == "done" and final["final_position_mm"] == {"x": 0.0, "y": 0.0}
        assert final["contour_error_um"]["max"] <= 30.0
        assert stopped != final["final_position_mm"]
        assert f"approach to line {line}" in d.log_text()


def test_embedded_run_from_line_needs_confirmation(tmp_path: Path) -> None:
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    env = {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}
    base = [*CNCCTL, "run", str(program), "--json", "--virtual-time", "--from-line", "5"]
    declined = subprocess.run(base, capture_output=True, text=True, env=env,
                              stdin=subprocess.DEVNULL, timeout=60)
    assert declined.returncode == 2 and "nothing moved" in declined.stderr
    t0 = time.monotonic()
    done = subprocess.run([*base, "--yes"], capture_output=True, text=True, env=env,
                          stdin=subprocess.DEVNULL, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "approach to machine X0.000 Y10.000" in done.stderr.replace("X30.000", "X0.000") \
        or "approach to machine X30.000 Y10.000" in done.stderr
    final = json.loads(done.stdout.splitlines()[-1])
    assert final["final_position_mm"] == {"x": 0.0, "y": 0.0}
    assert time.monotonic() - t0 < 30
    inside = subprocess.run([*CNCCTL, "run", str(REPO / "nc_programs/naca2415.nc"), "--json",
                             "--virtual-time", "--from-line", "6", "--yes"],
                            capture_output=True, text=True, env=env, timeout=60)
    assert inside.returncode == 2 and "line 6" in inside.stderr  # inside a NURBS block
