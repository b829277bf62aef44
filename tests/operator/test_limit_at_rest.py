"""Limit switches watched at rest too, through cncd from outside: a switch that opens while the
machine is idle, or while a job is held, latches FAULT naming it; one the machine already stands
on after a reset does not fault again until it closes and opens anew."""

from __future__ import annotations

import time
from pathlib import Path

from daemon_helpers import Cncd, open_switch, running_cncd, start_run, wait_moving
from test_fault_states import _slow_program, _wait_state


def _still_idle_s(d: Cncd, duration_s: float) -> None:
    deadline = time.monotonic() + duration_s
    while time.monotonic() < deadline:
        assert d.status()["state"] == "IDLE"
        time.sleep(0.05)


def test_a_limit_switch_opening_while_idle_latches_a_fault_naming_it(tmp_path: Path) -> None:
    trip = tmp_path / "limit-input"
    with running_cncd(tmp_path, "--drive-option", f"limit_input_file={trip}") as d:
        assert d.cncctl("reset").returncode == 0
        _still_idle_s(d, 0.3)
        open_switch(trip, "y-")
        status = _wait_state(d, "FAULT", timeout_s=10.0)
        assert status["fault"] == "hard limit: Y- limit switch tripped (machine at rest)"
        assert d.cncctl("jog", "X+1").returncode == 2  # latched until reset
        # reset with the switch still open: the machine stands on it, no fault again
        assert d.cncctl("reset").returncode == 0
        _still_idle_s(d, 0.5)
        trip.unlink()
        _still_idle_s(d, 0.3)
        open_switch(trip, "x+")  # another switch (or the same one again) opens: a fault
        status = _wait_state(d, "FAULT", timeout_s=10.0)
        assert status["fault"] == "hard limit: X+ limit switch tripped (machine at rest)"


def test_a_limit_switch_opening_during_a_hold_faults_the_held_job(tmp_path: Path) -> None:
    trip = tmp_path / "limit-input"
    with running_cncd(tmp_path, "--drive-option", f"limit_input_file={trip}") as d:
        assert d.cncctl("reset").returncode == 0
        run = start_run(d, _slow_program(tmp_path))
        try:
            wait_moving(run, after_s=0.2)
            assert d.cncctl("hold").returncode == 0
            _wait_state(d, "HELD", timeout_s=10.0)
            open_switch(trip, "x-")
            run.communicate(timeout=30)
        finally:
            run.kill()
            run.wait()
        assert run.returncode == 3
        status = _wait_state(d, "FAULT", timeout_s=10.0)
        assert status["fault"] == "hard limit: X- limit switch tripped"
