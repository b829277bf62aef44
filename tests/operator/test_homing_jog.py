"""Homing and jogging through cncd, from outside: a real daemon on the sim card with switches."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import yaml
from daemon_helpers import CNCCTL, REPO, running_cncd


def switches_config(tmp_path: Path) -> Path:
    """config/xy_table_switches.yaml with the table powered up 9 mm from each switch while its
    counters read 0 (so homing has to find where it really is)."""
    data = yaml.safe_load((REPO / "config/xy_table_switches.yaml").read_text())
    data["drive"]["options"] = {**data["drive"].get("options", {}),
                                "true_start_mm": [-140.0, 140.0], "start_mm": [0.0, 0.0]}
    path = tmp_path / "switches.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_runs_refused_until_homed_then_homing_sets_machine_position(tmp_path: Path) -> None:
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G1 X-140 Y140 F1200\nM2\n")
    with running_cncd(tmp_path, "--config", str(switches_config(tmp_path))) as d:
        d.cncctl("reset")
        status = d.status()
        assert status["homed"] == {"x": False, "y": False}
        refused = d.cncctl("run", str(program), "--json")
        assert refused.returncode == 2 and "not homed: X, Y" in refused.stderr
        done = d.cncctl("home")
        assert done.returncode == 0, done.stdout + done.stderr
        status = d.status()
        assert status["homed"] == {"x": True, "y": True} and status["state"] == "IDLE"
        assert status["position_mm"] == {"x": -145.0, "y": 145.0}  # final_mm of each axis
        ran = d.cncctl("run", str(program), "--json")
        final = json.loads(ran.stdout.splitlines()[-1])
        assert ran.returncode == 0 and final["final_position_mm"] == {"x": -140.0, "y": 140.0}


def test_jog_stops_at_the_soft_limit_and_continuous_jog_times_out(tmp_path: Path) -> None:
    with running_cncd(tmp_path, "--config", str(switches_config(tmp_path))) as d:
        d.cncctl("reset")
        assert d.cncctl("home").returncode == 0
        bad = d.cncctl("jog", "Q+3")
        assert bad.returncode == 2
        jog = d.cncctl("jog", "X-10", "--feed", "3000")  # from -145: the limit is -150
        assert jog.returncode == 0, jog.stderr
        assert "stopped at the soft limit" in jog.stdout
        x = d.status()["position_mm"]["x"]
        assert -150.0 <= x <= -149.998  # at the limit, never beyond
        again = d.cncctl("jog", "X-1", "--feed", "3000")
        assert again.returncode == 2 and "at the soft limit" in again.stderr
        assert d.status()["position_mm"]["x"] >= -150.0
        t0 = time.monotonic()
        cont = subprocess.run([*CNCCTL, "jog", "Y-", "--feed", "600", "--timeout", "0.6",
                               "--socket", d.socket_path], capture_output=True, text=True,
                              timeout=30, stdin=subprocess.DEVNULL)
        assert cont.returncode == 0, cont.stderr
        assert "aborted" in cont.stdout and "time-out" in cont.stdout
        assert time.monotonic() - t0 < 10
        y = d.status()["position_mm"]["y"]
        assert 138.0 < y < 145.0  # moved about 0.6 s at 10 mm/s, then stopped
        assert d.status()["state"] == "IDLE"


def test_estop_during_homing_halts_it(tmp_path: Path) -> None:
    data = yaml.safe_load(switches_config(tmp_path).read_text())
    data["drive"]["options"]["true_start_mm"] = [0.0, 0.0]  # 149 mm to go: seconds of search
    path = tmp_path / "far.yaml"
    path.write_text(yaml.safe_dump(data))
    with running_cncd(tmp_path, "--config", str(path)) as d:
        d.cncctl("reset")
        homing = subprocess.Popen([*CNCCTL, "home", "--socket", d.socket_path],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 10
            while d.status()["state"] != "HOMING":
                assert time.monotonic() < deadline
                time.sleep(0.05)
            time.sleep(0.3)
            assert d.cncctl("estop").returncode == 0
            out, _ = homing.communicate(timeout=20)
        finally:
            homing.kill()
        # Aborted by the e-stop: exit 4, and it says so (it printed "None" and exited 1).
        assert homing.returncode == 4, out
        first = out.splitlines()[0]
        assert not first.startswith("cncctl home: None") and "e-stop" in first, out
        status = d.status()
        assert status["state"] == "ESTOP" and status["homed"] == {"x": False, "y": False}
        assert "e-stop" in (status["last_homing"] or "")
        p1 = status["position_mm"]
        time.sleep(0.3)
        assert d.status()["position_mm"] == p1  # standing still


def test_embedded_run_refused_unhomed_and_homes_with_home(tmp_path: Path) -> None:
    import os
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G1 X-140 Y140 F1200\nM2\n")
    env = {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}
    base = [*CNCCTL, "run", str(program), "--config", str(switches_config(tmp_path)),
            "--virtual-time", "--json"]
    refused = subprocess.run(base, capture_output=True, text=True, env=env, timeout=60,
                             stdin=subprocess.DEVNULL)
    assert refused.returncode == 2 and "--home" in refused.stderr
    done = subprocess.run([*base, "--home"], capture_output=True, text=True, env=env,
                          timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr
    assert "homing X, Y" in done.stderr
    final = json.loads(done.stdout.splitlines()[-1])
    assert final["final_position_mm"] == {"x": -140.0, "y": 140.0}


def test_a_jog_feed_below_the_programs_minimum_is_refused_before_any_job() -> None:
    import pytest

    from controller.config import load_config
    from controller.operator.daemon.manual import jog_program
    from controller.operator.daemon.protocol import ProtocolError

    config = load_config("xy_table")
    with pytest.raises(ProtocolError, match="jog feed must be from 1 to"):
        jog_program(config, {"x": 0.0, "y": 0.0}, "x", 1.0, 1, 0.5)
    text, _ = jog_program(config, {"x": 0.0, "y": 0.0}, "x", 1.0, 1, 1.0)
    assert "F1.000" in text
