"""Feed hold and resume on the CANopen and serial backends, against their simulated peers."""

from __future__ import annotations

import json
import os
import select
import subprocess
import time
from pathlib import Path

import pytest
from test_canopen_process import CLI, ROOT
from test_canopen_process import peer as canopen_peer
from test_serial_card import peer as serial_peer

LINE = "G21 G90 G64 F1200\nG1 X20\nG1 Y5\nM2\n"  # about 1.3 s


def _events_until(proc: subprocess.Popen, state: str, timeout_s: float = 30.0) -> list[dict]:
    assert proc.stdout is not None
    seen: list[dict] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.5)
        if not ready:
            continue
        line = proc.stdout.readline()
        if not line:
            break
        event = json.loads(line)
        seen.append(event)
        if event.get("state") == state or event.get("event") == state:
            return seen
    raise AssertionError(f"never {state}: {seen[-3:]}")


def _hold_and_resume(tmp_path: Path, config: str, device_option: str) -> dict:
    program = tmp_path / "line.nc"
    program.write_text(LINE)
    env = {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}
    proc = subprocess.Popen([*CLI, "run", str(program), "--config", config, "--drive-option",
                             device_option, "--json"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=ROOT)
    try:
        assert proc.stdin is not None
        _events_until(proc, "running")
        time.sleep(0.3)
        proc.stdin.write(" ")
        proc.stdin.flush()
        held = _events_until(proc, "held")[-1]
        proc.stdin.write(" ")
        proc.stdin.flush()
        done = _events_until(proc, "done")[-1]
        proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0
    x, y = held["position_mm"]
    assert 0.0 < x < 20.0 and y == 0.0  # held on the first line, on the path
    assert done["final_position_mm"] == {"x": 20.0, "y": 5.0} and done["underruns"] == 0
    return done


@pytest.mark.parametrize("backend", ["canopen", "serial"])
def test_hold_and_resume_on_a_peer(tmp_path: Path, backend: str) -> None:
    if backend == "canopen":
        with canopen_peer() as (_, path):
            done = _hold_and_resume(tmp_path, "canopen", f"channel={path}")
    else:
        with serial_peer() as (port, _):
            done = _hold_and_resume(tmp_path, "serial", f"port={port}")
    assert done["contour_error_um"]["max"] <= 30.0
