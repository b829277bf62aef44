"""The canopen backend across processes: `cncctl simdrive canopen` behind a fake slcan pty."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from controller.config import load_config
from drivers.canopen import bringup
from drivers.canopen import cia402 as c
from drivers.canopen.options import parse_options

ROOT = Path(__file__).resolve().parents[2]
PROGRAM = str(ROOT / "nc_programs" / "naca2415.nc")
CLI = [sys.executable, "-m", "controller.operator.cli"]
CONFIG = load_config("canopen")


@contextmanager
def peer(*options: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """The simulated drives in their own process; yields (process, pty path)."""
    args = [*CLI, "simdrive", "canopen"]
    for option in options:
        args += ["--option", option]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready, "simdrive printed no device path within 20 s"
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/"), (path, proc.stderr.read() if proc.poll() else "")
        yield proc, path
    finally:
        proc.kill()
        proc.wait(timeout=10)


def run(path: str, *extra: str, timeout_s: float = 30.0) -> tuple[int, dict[str, Any], str]:
    """`cncctl run naca2415 --config canopen --json` on the peer: (exit code, last event,
    stderr)."""
    out = subprocess.run([*CLI, "run", PROGRAM, "--config", "canopen", "--drive-option",
                          f"channel={path}", "--json", *extra], capture_output=True, text=True,
                         timeout=timeout_s, cwd=ROOT)
    events = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    return out.returncode, events[-1] if events else {}, out.stderr


def drive_states(path: str, axes: str = "xy") -> list[tuple[str, int]]:
    """(CiA 402 state, 0x603F) of the simulated drives, read by SDO through the pty."""
    o = parse_options(CONFIG, dict(CONFIG.drive.options) | {"channel": path})
    network = bringup.connect(o)
    try:
        nodes = bringup.add_nodes(network, o)
        return [(c.state_of(bringup.sdo_read(n, a, c.STATUSWORD)),
                 bringup.sdo_read(n, a, c.ERROR_CODE))
                for n, a in zip(nodes, "xy", strict=True) if a in axes]
    finally:
        network.disconnect()


def wait_running(runner: subprocess.Popen[str]) -> bool:
    """Read `cncctl run --json` progress until the program has executed frames."""
    for line in runner.stdout:
        event = json.loads(line)
        if event.get("state") == "running" and event.get("executed_s", 0.0) > 0.0:
            return True
    return False


def not_enabled(states: list[tuple[str, int]]) -> bool:
    return all(state != "OPERATION ENABLED" for state, _ in states)


def test_airfoil_on_the_peer_matches_the_sim_card() -> None:
    sim = subprocess.run([*CLI, "run", PROGRAM, "--json"], capture_output=True, text=True,
                         timeout=30, cwd=ROOT)
    expected = json.loads(sim.stdout.splitlines()[-1])
    with peer() as (_, path):
        code, last, err = run(path)
        assert (code, last["event"], last["message"]) == (0, "done", ""), err
        for key in ("pulses", "final_position_mm", "planned_time_s", "position_known",
                    "underruns"):
            assert last[key] == expected[key], key
        assert abs(last["contour_error_um"]["max"] - expected["contour_error_um"]["max"]) < 1.0
        assert [s for s, _ in drive_states(path)] == ["READY TO SWITCH ON"] * 2


def test_drive_fault_mid_program_stops_and_names_the_code() -> None:
    with peer("drive_fault_after_s=0.5", "drive_fault_code=0x2310") as (_, path):
        t0 = time.monotonic()
        code, last, err = run(path)
        assert code == 3 and last["event"] == "fault", err
        assert "X axis drive (node 1) EMCY 0x2310 over-current" in last["message"]
        # injected 0.5 s (of SYNC cycles) after enable; the program would run 1.137 s
        assert last["motion_time_s"] < 1.0 and time.monotonic() - t0 < 10.0
        assert last["position_known"] and last["final_position_mm"]["x"] != 0.0
        states = drive_states(path)
        assert states[0] == ("FAULT", 0x2310) and not_enabled(states)


def test_following_error_emcy_ends_in_a_latched_fault() -> None:
    with peer("lag_mm=2.0", "lag_after_s=0.5", "fault_axis=y") as (_, path):
        code, last, err = run(path)
        assert code == 3 and last["event"] == "fault", err
        assert "Y axis drive (node 2) EMCY 0x8611 following error" in last["message"]
        assert last["motion_time_s"] < 1.0 and last["position_known"]
        states = drive_states(path)
        assert states[1] == ("FAULT", 0x8611) and not_enabled(states)


def test_silent_drive_is_lost_with_the_last_known_position() -> None:
    with peer("silent_after_s=0.5") as (_, path):
        code, last, err = run(path)
        assert code == 3 and last["event"] == "fault", err
        assert "lost X axis drive (node 1)" in last["message"]
        assert last["motion_time_s"] < 1.0  # 0.5 s + 100 SYNC cycles without TPDO1
        assert last["position_known"] is False
        assert abs(last["final_position_mm"]["x"]) > 1.0  # last known, mid-airfoil
        assert drive_states(path, axes="y")[0][0] != "OPERATION ENABLED"  # x cannot answer


def test_peer_killed_mid_program_is_lost_communication() -> None:
    """The butterfly (6.8 s), not the airfoil (1.1 s): on a loaded machine the airfoil was
    done before the peer was killed, and its last line, read ahead by wait_running's
    iteration, never reached communicate()."""
    with peer() as (proc, path):
        runner = subprocess.Popen([*CLI, "run", str(ROOT / "nc_programs" / "butterfly.nc"),
                                   "--config", "canopen", "--drive-option", f"channel={path}",
                                   "--json"],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  cwd=ROOT)
        try:
            assert wait_running(runner), "the program never started moving"
            proc.kill()  # the peer dies mid-program (the adapter is unplugged)
            t_kill = time.monotonic()
            out, err = runner.communicate(timeout=20)
            assert out.strip(), err
            last = json.loads(out.splitlines()[-1])
            assert runner.returncode == 3 and last["event"] == "fault", err
            assert "lost communication with the CAN adapter" in last["message"]
            assert last["position_known"] is False
            assert time.monotonic() - t_kill < 5.0
        finally:
            runner.kill()
            runner.wait(timeout=10)


def test_sdo_abort_during_bringup_moves_nothing() -> None:
    with peer("sdo_abort_index=0x6065") as (_, path):
        code, _, err = run(path)
        assert code == 2
        assert "SDO write of 0x6065" in err and "aborted" in err and "nothing moved" in err
        assert [s for s, _ in drive_states(path)] == ["SWITCH ON DISABLED"] * 2


def test_killed_controller_faults_the_drives_on_their_heartbeat_consumer() -> None:
    with peer() as (_, path):
        runner = subprocess.Popen([*CLI, "run", PROGRAM, "--config", "canopen",
                                   "--drive-option", f"channel={path}", "--json"],
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                  cwd=ROOT, start_new_session=True)
        try:
            assert wait_running(runner), "the program never started moving"
            os.killpg(runner.pid, signal.SIGKILL)  # the controller and its children
            runner.wait(timeout=10)
            deadline = time.monotonic() + 3.0
            states = drive_states(path)
            while states != [("FAULT", c.EMCY_HEARTBEAT)] * 2 and time.monotonic() < deadline:
                time.sleep(0.05)
                states = drive_states(path)
            assert states == [("FAULT", c.EMCY_HEARTBEAT)] * 2
            # A new run fault-resets them at bring-up, reads where they stopped and checks
            # the program from there: naca2415's G6.2 must start where the tool is, so it is
            # refused by name (exit 2) and the drives are left disabled: no jump, no motion.
            code, _, err = run(path)
            assert code == 2, err
            assert "the first G6.2 control point must be the current position" in err
            assert not_enabled(drive_states(path))
        finally:
            if runner.poll() is None:
                os.killpg(runner.pid, signal.SIGKILL)
            runner.wait(timeout=10)


def test_check_without_an_adapter_says_so_and_exits_2() -> None:
    out = subprocess.run([*CLI, "check", PROGRAM, "--config", "canopen", "--drive-option",
                          "channel=/dev/cnc-no-such-adapter"], capture_output=True, text=True,
                         timeout=30, cwd=ROOT)
    assert out.returncode == 2
    assert "no CAN adapter at /dev/cnc-no-such-adapter" in out.stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM])
def test_simdrive_prints_its_device_first_and_exits_0_on_sigterm(sig: int) -> None:
    with peer() as (proc, path):
        assert os.path.exists(path)
        proc.send_signal(sig)
        assert proc.wait(timeout=5) == 0
