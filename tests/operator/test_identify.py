"""`cncctl identify` from outside: a real cncctl process on the sim card (a plant off its model),
on the serial and CANopen peers in their own processes, its refusals, and its --output."""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from controller.config import load_config
from controller.servo.excitation import design
from controller.servo.fit import simulate_error_mm
from controller.servo.model import mismatched

REPO = Path(__file__).resolve().parents[2]
CNCCTL = [sys.executable, "-m", "controller.operator.cli"]
XY = str(REPO / "config/xy_table.yaml")
ENV = os.environ | {"CNCD_SOCKET": "/nonexistent/cncd.sock"}  # embedded, whatever runs here


def _identify(*words: str, stdin: int | None = subprocess.DEVNULL,
              timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([*CNCCTL, "identify", *words], capture_output=True, text=True,
                          stdin=stdin, timeout=timeout_s, cwd=REPO, env=ENV)


def _gap(a: object, b: object) -> float:
    v = np.diff(design(0.001, 58.3, 2450.0, 10.0, seed=5).position_mm, prepend=0.0) / 0.001
    ea, eb = simulate_error_mm(a, v, 0.001), simulate_error_mm(b, v, 0.001)  # type: ignore
    return float(np.linalg.norm(ea - eb) / np.linalg.norm(eb))


def test_identify_on_a_mismatched_sim_card_finds_its_plant_and_writes_a_config(
        tmp_path: Path) -> None:
    out = tmp_path / "identified.yaml"
    done = _identify("x", "y", "--config", XY, "--yes", "--virtual-time", "--drive-option",
                     "plant_pole_pct=20", "--output", str(out))
    assert done.returncode == 0, done.stderr
    assert "X will move within -1.451..1.797 mm" in done.stderr
    assert "X  fit on held-out data" in done.stdout and "usable" in done.stdout
    found = re.search(r"naca2415.nc planned with the model in force: contour error max "
                      r"([0-9.]+) um through the model in force, ([0-9.]+) um through the "
                      r"identified loops", done.stdout)
    assert found and float(found[1]) < 30.0 and float(found[2]) > 0.0, done.stdout
    nominal = load_config(XY)
    written = load_config(str(out))
    for name in ("x", "y"):
        plant = mismatched(nominal.axis(name).servo, 20.0)
        assert _gap(written.axis(name).servo, plant) < 0.1 * _gap(nominal.axis(name).servo,
                                                                   plant)
    # The rest of the config is the one in force, and the drive option is not baked in.
    assert written.interpolator == nominal.interpolator
    assert dict(written.drive.options) == dict(nominal.drive.options)
    sim = subprocess.run([*CNCCTL, "simulate", "nc_programs/naca2415.nc", "--config", str(out)],
                         capture_output=True, text=True, timeout=120, cwd=REPO, env=ENV)
    assert sim.returncode == 0, sim.stderr
    again = _identify("x", "--config", XY, "--yes", "--virtual-time", "--output", str(out))
    assert again.returncode == 2 and "--force" in again.stderr and "exciting" not in again.stderr


@pytest.mark.parametrize("words,why", [
    (("--config", str(REPO / "config/xy_table_switches.yaml"), "--yes", "--virtual-time"),
     "not homed"),
    (("x", "--config", XY, "--yes", "--virtual-time", "--drive-option", "start_mm=[149.5, 0]"),
     "travel too short"),
    (("x", "--config", XY, "--yes", "--virtual-time", "--window", "0.5"), "travel too short"),
    (("x", "--config", XY, "--virtual-time"), "not confirmed: nothing moved"),
    (("w", "--config", XY, "--yes", "--virtual-time"), "no such axis"),
    (("x", "--config", XY, "--yes", "--virtual-time", "--duration", "0"), "duration"),
])
def test_refusals_move_nothing_and_say_why(words: tuple[str, ...], why: str) -> None:
    done = _identify(*words)
    assert done.returncode == 2, done.stderr
    assert why in done.stderr and "exciting" not in done.stderr and not done.stdout


def test_a_stop_signal_ends_the_excitation_along_its_path_and_writes_nothing(
        tmp_path: Path) -> None:
    out = tmp_path / "never.yaml"
    proc = subprocess.Popen([*CNCCTL, "identify", "x", "--config", XY, "--yes", "--output",
                             str(out)], stderr=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, cwd=REPO, env=ENV)
    try:
        deadline = time.monotonic() + 60.0
        while "exciting X" not in (line := proc.stderr.readline()):  # type: ignore[union-attr]
            assert line and time.monotonic() < deadline
        time.sleep(1.0)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 4, err
    assert "brought back to rest at its start" in err and not out.exists()


@contextmanager
def _peer(backend: str) -> Iterator[str]:
    """`cncctl simdrive BACKEND` in its own process; its device path; killed by pid."""
    proc = subprocess.Popen([*CNCCTL, "simdrive", backend], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, bufsize=0, cwd=REPO, env=ENV)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready, "simdrive printed no device path within 20 s"
        yield proc.stdout.readline().decode().strip()  # type: ignore[union-attr]
    finally:
        proc.kill()
        proc.wait(timeout=10)


@pytest.mark.parametrize("backend,option", [("serial", "port"), ("canopen", "channel")])
def test_identify_on_a_peer_in_its_own_process(backend: str, option: str) -> None:
    with _peer(backend) as path:
        done = _identify("x", "--config", str(REPO / f"config/{backend}.yaml"), "--yes",
                         "--drive-option", f"{option}={path}")
    assert done.returncode == 0, done.stderr
    fit = next(line for line in done.stdout.splitlines() if "held-out" in line)
    assert float(fit.split(":")[1].split("%")[0]) > 90.0, fit  # the peer runs the model itself


def test_a_drive_with_a_latched_fault_is_refused_before_any_motion(tmp_path: Path) -> None:
    fault = tmp_path / "fault"
    fault.write_text("")
    done = _identify("x", "--config", XY, "--yes", "--virtual-time", "--drive-option",
                     f"drive_fault_file={fault}")
    assert done.returncode == 2, done.stderr
    assert "halted" in done.stderr and "drive fault" in done.stderr
    assert "exciting" not in done.stderr
