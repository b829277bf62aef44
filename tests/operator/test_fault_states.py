"""Every stop ends in the right state, from outside: a real cncd on its socket, real cncctl
processes, a serial peer in its own process killed to lose the position, and a run whose
standard input is at its end."""

from __future__ import annotations

import json
import os
import select
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import yaml
from daemon_helpers import CNCCTL, REPO, Cncd, running_cncd, start_run, wait_moving


def _wait_state(d: Cncd, state: str, timeout_s: float = 20.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while (status := d.status())["state"] != state:
        assert time.monotonic() < deadline, status
        time.sleep(0.05)
    return status


def _slow_program(tmp_path: Path) -> Path:
    """Seconds of slow moves near X0 Y0 (a job to hold and abort)."""
    program = tmp_path / "slow.nc"
    moves = "".join(f"G1 X{x} Y{y}\n" for _ in range(20) for x, y in
                    ((5, 0), (5, 5), (0, 5), (0, 0)))
    program.write_text("G21 G90 G64 F600\n" + moves + "M2\n")
    return program


@contextmanager
def _serial_peer(tmp_path: Path, *options: str) -> Iterator[tuple[subprocess.Popen, Path]]:
    """`cncctl simdrive serial` in its own process and a config on its pty; killed by pid."""
    words = [w for o in options for w in ("--option", o)]
    proc = subprocess.Popen([*CNCCTL, "simdrive", "serial", *words], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, bufsize=0, cwd=REPO)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready, "simdrive printed no device path within 20 s"
        port = proc.stdout.readline().decode().strip()  # type: ignore[union-attr]
        data = yaml.safe_load((REPO / "config/serial.yaml").read_text())
        data["drive"]["options"]["port"] = port
        config = tmp_path / "serial.yaml"
        config.write_text(yaml.safe_dump(data))
        yield proc, config
    finally:
        proc.kill()
        proc.wait(timeout=10)


def test_abort_of_a_held_job_answers_the_state_it_leads_to(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, _slow_program(tmp_path))
        try:
            wait_moving(run, after_s=0.2)
            assert d.cncctl("hold").returncode == 0
            _wait_state(d, "HELD")
            abort = d.cncctl("abort")
            assert abort.returncode == 0 and abort.stdout.strip() == "cncctl abort: IDLE"
            run.communicate(timeout=30)
            assert run.returncode == 4
        finally:
            run.kill()
            run.wait()
        assert d.status()["state"] == "IDLE"


def test_jog_and_home_with_the_position_unknown_are_refused_saying_what_to_do(
        tmp_path: Path) -> None:
    with _serial_peer(tmp_path) as (peer, config), \
            running_cncd(tmp_path, "--config", str(config)) as d:
        assert d.cncctl("reset").returncode == 0
        peer.kill()  # the link is lost: nobody can say where the machine is
        peer.wait(timeout=10)
        for words in (("jog", "X+1"), ("home",)):
            done = d.cncctl(*words)
            assert done.returncode == 2, done.stdout + done.stderr
            assert "position-unknown" in done.stderr and "position is unknown" in done.stderr
            assert "`cncctl reset`" in done.stderr and "`cncctl home`" in done.stderr
        assert "internal error" not in d.log_text()
        assert d.status()["state"] == "IDLE"  # refused: nothing latched, nothing moved


def test_a_jog_that_moved_then_faulted_exits_3(tmp_path: Path) -> None:
    with _serial_peer(tmp_path) as (peer, config), \
            running_cncd(tmp_path, "--config", str(config)) as d:
        assert d.cncctl("reset").returncode == 0
        jog = subprocess.Popen([*CNCCTL, "jog", "X+50", "--feed", "600", "--socket",
                                d.socket_path], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               stdin=subprocess.DEVNULL, text=True)
        try:
            deadline = time.monotonic() + 20
            while ((d.status().get("position_mm") or {}).get("x") or 0.0) < 0.3:
                assert time.monotonic() < deadline and jog.poll() is None
                time.sleep(0.05)
            peer.kill()  # the link goes mid-jog: a fault after 0.3 mm or more of motion
            out, err = jog.communicate(timeout=30)
        finally:
            jog.kill()
            jog.wait()
        assert jog.returncode == 3, out + err
        assert "fault" in out
        assert d.status()["state"] == "FAULT"


def test_run_through_cncd_refuses_the_options_it_cannot_honour(tmp_path: Path) -> None:
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G1 X1 F600\nM2\n")
    table = tmp_path / "offsets.json"
    table.write_text("{}")
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        for extra in (["--virtual-time"], ["--config", "xy_table"], ["--home"],
                      ["--offsets", str(table)], ["--drive-option", "realtime=false"]):
            done = d.cncctl("run", str(program), *extra)
            assert done.returncode == 2, (extra, done.stdout, done.stderr)
            assert extra[0] in done.stderr and "nothing moved" in done.stderr.lower()
        status = d.status()
        assert status["last_job"].get("program") is None  # no job reached the daemon
        assert status["position_mm"] == {"x": 0.0, "y": 0.0}


def test_an_embedded_run_at_m0_with_its_input_at_the_end_aborts(tmp_path: Path) -> None:
    program = tmp_path / "m0.nc"
    program.write_text("G21 G90 G64 F2400\nG1 X2\nM0\nG1 X0\nM2\n")
    env = {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}
    done = subprocess.run([*CNCCTL, "run", str(program), "--json", "--virtual-time"],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, env=env,
                          timeout=60)
    assert done.returncode == 4, done.stderr
    final = json.loads(done.stdout.splitlines()[-1])
    assert final["event"] == "aborted"
    assert "standard input closed while paused at line 3 (M0)" in done.stderr
    assert final["final_position_mm"] == {"x": 2.0, "y": 0.0}  # stopped at the pause


def test_a_drive_fault_during_an_abort_latches_fault_naming_both(tmp_path: Path) -> None:
    """Amax 50 mm/s^2 from 40 mm/s: the abort's stop lasts 1.5 s, and the drive faults 0.3 s
    into it. It was recorded as the abort, cncd went IDLE, and the next jog faulted at once."""
    data = yaml.safe_load((REPO / "config/xy_table.yaml").read_text())
    data["interpolator"]["max_accel_mm_s2"] = 50.0
    data["axes"]["x"]["travel_mm"] = [-1000.0, 1000.0]  # 13 s at 40 mm/s: aborted at speed
    fault = tmp_path / "drive-fault"
    data["drive"] = {"backend": "sim", "options": {"drive_fault_file": str(fault)}}
    config = tmp_path / "slow_stops.yaml"
    config.write_text(yaml.safe_dump(data))
    program = tmp_path / "long.nc"
    program.write_text("G21 G90 G64 G1 X600 F2400\nM2\n")  # 1.5 s to 40 mm/s, 13 s at it
    with running_cncd(tmp_path, "--config", str(config)) as d:
        d.cncctl("reset")
        run = start_run(d, program)
        try:
            wait_moving(run, after_s=2.0)
            assert d.cncctl("abort").returncode == 0
            time.sleep(0.3)  # the stop is under way (it has 1.5 s to go)
            fault.touch()
            out, err = run.communicate(timeout=30)
        finally:
            run.kill()
            run.wait()
        final = json.loads(out.splitlines()[-1])
        assert run.returncode == 3 and final["event"] == "fault", err
        assert final["message"].startswith("aborted by operator")
        assert final["message"].endswith("; then X axis drive fault 0x2310")
        status = d.status()
        assert status["state"] == "FAULT" and "then X axis drive fault" in status["fault"]
