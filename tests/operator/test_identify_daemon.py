"""`cncctl identify` through a real cncd (its sim card a plant off the model): the fit, the
--output the client writes, the refusals, and abort, e-stop (both sockets and the drive's
input) and a drive fault during it."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

from daemon_helpers import CNCCTL, REPO, Cncd, raw, running_cncd, start_run, wait_moving
from test_fault_states import _slow_program, _wait_state
from test_identify import _gap

from controller.config import load_config
from controller.servo.model import mismatched

XY = str(REPO / "config/xy_table.yaml")
OFF_MODEL = ("--config", XY, "--drive-option", "plant_pole_pct=20")


def _held_out(stdout: str, axis: str) -> tuple[float, float]:
    """(identified, model in force) held-out fit in % from the report's line."""
    line = next(x for x in stdout.splitlines() if x.startswith(f"{axis}  fit on held-out"))
    words = line.split(":")[1].split("%")
    return float(words[0]), float(words[1].split(",")[1])


def _start_identify(d: Cncd, *words: str) -> subprocess.Popen:
    """`cncctl identify` through d, returned once it says the first axis is moving."""
    proc = subprocess.Popen([*CNCCTL, "identify", *words, "--yes", "--socket", d.socket_path],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, text=True, cwd=REPO)
    deadline = time.monotonic() + 30.0
    while "exciting X" not in (line := proc.stderr.readline()):  # type: ignore[union-attr]
        assert line and time.monotonic() < deadline, f"identify did not start: {line}"
    return proc


def _end(proc: subprocess.Popen) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=30)
    finally:
        proc.kill()
        proc.wait()


def test_identify_through_cncd_finds_the_plant_and_the_client_writes_the_config(
        tmp_path: Path) -> None:
    out = tmp_path / "identified.yaml"
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        d.cncctl("reset")
        done = d.cncctl("identify", "x", "--yes", "--output", str(out), timeout_s=120)
        assert done.returncode == 0, done.stderr
        assert "X will move within -1.451..1.797 mm" in done.stderr
        assert "exciting X" in done.stderr and f"wrote {out}" in done.stderr
        identified, in_force = _held_out(done.stdout, "X")
        assert identified > 90.0 and in_force < identified - 20.0, done.stdout
        assert "naca2415.nc planned with the model in force" in done.stdout
        status = d.status()
        assert status["state"] == "IDLE" and status["drives"] == "enabled"
        last = status["last_identify"]
        assert last["event"] == "done" and abs(last["fits"]["x"]["fit_pct"] - identified) < 0.1
        assert "config_yaml" not in last  # kept in status without the config text
        assert f"last identify: done (held-out fit X {identified:.1f} %)" in d.cncctl(
            "status").stdout
        # Options only an embedded identify honours are refused, nothing sent.
        for words in (("--config", XY), ("--virtual-time",), ("--home",),
                      ("--drive-option", "plant_pole_pct=0")):
            refused = d.cncctl("identify", "x", "--yes", *words)
            assert refused.returncode == 2 and "cannot honour" in refused.stderr, words
            assert "exciting" not in refused.stderr and d.status()["last_identify"] == last
        again = d.cncctl("identify", "x", "--yes", "--output", str(out))
        assert again.returncode == 2 and "--force" in again.stderr
    # The journal keeps it: a restarted cncd still says how the last identify went.
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        assert d.status()["last_identify"] == {**last, "at": d.status()["last_identify"]["at"]}
    check = subprocess.run([*CNCCTL, "check", "nc_programs/naca2415.nc", "--config", str(out)],
                           capture_output=True, text=True, timeout=60, cwd=REPO)
    assert check.returncode == 0, check.stderr
    nominal, written = load_config(XY), load_config(str(out))
    plant = mismatched(nominal.axis("x").servo, 20.0)
    assert _gap(written.axis("x").servo, plant) < 0.1 * _gap(nominal.axis("x").servo, plant)
    assert written.axis("y").servo == nominal.axis("y").servo  # not identified: as it was
    assert dict(written.drive.options) == dict(nominal.drive.options)  # cncd's option not baked


def test_identify_is_refused_in_estop_while_a_job_runs_and_for_bad_fields(
        tmp_path: Path) -> None:
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        refused = d.cncctl("identify", "x", "--yes")  # ESTOP at start-up
        assert refused.returncode == 2 and "estop" in refused.stderr, refused.stderr
        d.cncctl("reset")
        run = start_run(d, _slow_program(tmp_path))
        try:
            wait_moving(run, after_s=0.2)
            busy = d.cncctl("identify", "x", "--yes")
            assert busy.returncode == 2 and "busy" in busy.stderr, busy.stderr
            assert d.status()["state"] == "RUNNING"
            assert d.cncctl("abort").returncode == 0
            run.communicate(timeout=30)
        finally:
            run.kill()
            run.wait()
        _wait_state(d, "IDLE")
        for fields in ({"window_mm": "10"}, {"duration_s": 0}, {"axes": "x"},
                       {"from_mm": {"x": True}}, {"speed": 1}):
            reply = raw(d.socket_path, json.dumps({"cmd": "identify", **fields}).encode()
                        + b"\n")
            assert reply[0]["error"] == "bad-field", (fields, reply)
        short = d.cncctl("identify", "x", "--yes", "--window", "0.5")
        assert short.returncode == 2 and "no-room" in short.stderr, short.stderr
        moved = raw(d.socket_path, b'{"cmd": "identify", "axes": ["x"], "from_mm": {"x": 3}}\n')
        assert moved[0]["error"] == "moved", moved
        assert d.status()["state"] == "IDLE" and d.status()["last_identify"] is None


def test_abort_estop_and_sigterm_stop_identify_along_its_path(tmp_path: Path) -> None:
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        d.cncctl("reset")
        proc = _start_identify(d, "x", "y")
        # Soon after X starts (its excitation lasts seconds, but a loaded machine may deliver
        # the "exciting X" line late): the abort must find X moving.
        time.sleep(0.2)
        # Through the socket itself: a cncctl process takes seconds to start on a loaded PC.
        assert raw(d.socket_path, b'{"cmd": "status"}\n')[0]["state"] == "IDENTIFYING"
        abort = raw(d.socket_path, b'{"cmd": "abort"}\n')[0]
        assert abort["ok"] and abort["state"] == "IDLE", abort
        out, err = _end(proc)
        assert proc.returncode == 4, err
        assert "X brought back to rest at its start" in err and "exciting Y" not in err
        status = _wait_state(d, "IDLE")
        assert status["drives"] == "enabled" and status["last_identify"]["event"] == "aborted"
        assert all(abs(v) < 0.01 for v in status["position_mm"].values()), status

        proc = _start_identify(d, "x")
        time.sleep(1.0)
        assert d.cncctl("estop").returncode == 0
        out, err = _end(proc)
        assert proc.returncode == 4 and "e-stop" in err, err
        status = d.status()
        assert status["state"] == "ESTOP" and status["drives"] == "disabled"
        assert status["position_mm"] is not None
        assert all(abs(v) < 0.01 for v in status["position_mm"].values()), status
        assert d.cncctl("identify", "x", "--yes").returncode == 2  # latched: reset first

        d.cncctl("reset")  # the control socket's estop (cncctl uses the e-stop socket)
        proc = _start_identify(d, "x")
        time.sleep(0.5)
        assert raw(d.socket_path, b'{"cmd": "estop"}\n')[0]["state"] == "ESTOP"
        out, err = _end(proc)
        assert proc.returncode == 4 and "e-stop by operator (control socket" in err, err
        status = d.status()
        assert status["state"] == "ESTOP" and status["drives"] == "disabled"

        d.cncctl("reset")  # SIGTERM: cncd stops it along its path, tells the client, exits
        proc = _start_identify(d, "x")
        time.sleep(0.5)
        d.proc.send_signal(signal.SIGTERM)
        out, err = _end(proc)
        assert proc.returncode == 4 and "daemon stopping (SIGTERM)" in err, err
        assert d.proc.wait(timeout=30) == 0


def test_the_estop_input_then_a_drive_fault_during_identify(tmp_path: Path) -> None:
    trip, fault = tmp_path / "estop-input", tmp_path / "drive-fault"
    with running_cncd(tmp_path, *OFF_MODEL, "--drive-option", f"estop_input_file={trip}",
                      "--drive-option", f"drive_fault_file={fault}") as d:
        d.cncctl("reset")
        proc = _start_identify(d, "x")
        time.sleep(0.5)
        trip.touch()
        out, err = _end(proc)
        assert proc.returncode == 4 and "e-stop input" in err, err
        status = _wait_state(d, "ESTOP")
        assert status["drives"] == "disabled" and status["position_mm"] is not None
        trip.unlink()
        assert d.cncctl("reset").returncode == 0

        proc = _start_identify(d, "x")
        time.sleep(0.5)
        fault.touch()
        out, err = _end(proc)
        assert proc.returncode == 3, err
        assert "drive fault" in err and "nothing identified" in err
        status = d.status()
        assert status["state"] == "FAULT" and "drive fault" in status["fault"]
        assert status["last_identify"]["event"] == "fault"


def test_a_daemon_killed_during_identify_says_so_after_its_restart(tmp_path: Path) -> None:
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        d.cncctl("reset")
        proc = _start_identify(d, "x")
        time.sleep(0.5)
        d.proc.kill()
        d.proc.wait(timeout=10)
        _end(proc)
        assert proc.returncode != 0
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        status = d.status()
        last = status["last_identify"]
        assert last["event"] == "interrupted" and "nothing identified" in last["message"]
        assert status["state"] == "ESTOP"  # as after any start: nothing moves by itself
