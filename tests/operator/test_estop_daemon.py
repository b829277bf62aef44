"""The e-stop through cncd, from outside: `cncctl estop` and the drive's e-stop input (the sim
card's, and the serial card's in its own process) stop the job, disable the drives, and latch
until a reset, which the open input refuses."""

from __future__ import annotations

import json
import time
from pathlib import Path

import yaml
from daemon_helpers import Cncd, running_cncd, start_run, wait_moving
from test_fault_states import _serial_peer, _slow_program, _wait_state


def _stands_still(d: Cncd) -> None:
    before = d.status()["position_mm"]
    time.sleep(0.3)
    assert d.status()["position_mm"] == before


def _enabled_again(d: Cncd) -> None:
    done = d.cncctl("reset")
    assert done.returncode == 0, done.stderr
    status = d.status()
    assert status["state"] == "IDLE" and status["drives"] == "enabled"
    jog = d.cncctl("jog", "Y+1")
    assert jog.returncode == 0, jog.stdout + jog.stderr


def test_cncctl_estop_stops_the_job_and_disables_the_drives_until_reset(
        tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        assert d.status()["drives"] == "disabled"  # ESTOP at start-up: the drives are off
        d.cncctl("reset")
        assert d.status()["drives"] == "enabled"
        run = start_run(d, _slow_program(tmp_path))
        try:
            wait_moving(run, after_s=0.2)
            estop = d.cncctl("estop")
            assert estop.returncode == 0 and estop.stdout.strip() == "cncctl estop: ESTOP"
            out, err = run.communicate(timeout=30)
        finally:
            run.kill()
            run.wait()
        final = json.loads(out.splitlines()[-1])
        assert run.returncode == 4 and final["event"] == "aborted", (final, err)
        assert "e-stop by operator" in final["message"]
        status = d.status()
        assert status["state"] == "ESTOP" and status["drives"] == "disabled"
        shown = d.cncctl("status").stdout
        assert "drives disabled (e-stop): `cncctl reset` enables them" in shown
        _stands_still(d)
        assert d.cncctl("jog", "X+1").returncode == 2  # latched
        _enabled_again(d)


def test_the_sim_cards_estop_input_estops_and_reset_waits_until_it_closes(
        tmp_path: Path) -> None:
    trip = tmp_path / "estop-input"
    with running_cncd(tmp_path, "--drive-option", f"estop_input_file={trip}") as d:
        d.cncctl("reset")
        run = start_run(d, _slow_program(tmp_path))
        try:
            wait_moving(run, after_s=0.2)
            trip.touch()
            out, err = run.communicate(timeout=30)
        finally:
            run.kill()
            run.wait()
        final = json.loads(out.splitlines()[-1])
        assert run.returncode == 4 and "e-stop input on the drive tripped" in final["message"]
        status = _wait_state(d, "ESTOP")
        assert status["drives"] == "disabled" and status["estop_input"] is True
        assert "e-stop input open" in d.cncctl("status").stdout
        _stands_still(d)
        refused = d.cncctl("reset")
        assert refused.returncode == 2 and "e-stop input on the drive is open" in refused.stderr
        assert d.status()["state"] == "ESTOP"
        trip.unlink()
        _enabled_again(d)


def test_the_serial_cards_estop_input_estops_an_idle_machine(tmp_path: Path) -> None:
    trip = tmp_path / "estop-input"
    with _serial_peer(tmp_path, f"estop_input_file={trip}") as (_, config), \
            running_cncd(tmp_path, "--config", str(config)) as d:
        reset = d.cncctl("reset")
        assert reset.returncode == 0, reset.stderr
        assert d.status()["drives"] == "enabled"
        trip.touch()
        status = _wait_state(d, "ESTOP")
        assert status["fault"] == "e-stop input on the drive tripped"
        assert status["drives"] == "disabled"
        assert d.cncctl("reset").returncode == 2
        trip.unlink()
        deadline = time.monotonic() + 10
        while d.status()["estop_input"]:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        _enabled_again(d)
        assert yaml.safe_load(config.read_text())["drive"]["backend"] == "serial"
