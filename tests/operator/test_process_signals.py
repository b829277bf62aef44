"""`cncctl` as a real process: SIGTERM and SIGHUP stop a run under control, a closed pipe ends
quietly, an oversized config is refused unread."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from daemon_helpers import children_of, running

REPO = Path(__file__).resolve().parents[2]
CNCCTL = [sys.executable, "-m", "controller.operator.cli"]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_decelerates_and_exits_4(sig: signal.Signals) -> None:
    proc = subprocess.Popen([*CNCCTL, "run", str(REPO / "nc_programs/naca2415.nc"), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        while True:  # wait until it moves
            event = json.loads(proc.stdout.readline())
            if event["event"] == "progress" and event.get("executed_s", 0) > 0.1:
                break
        children = children_of(proc.pid)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=20)
        final = json.loads(out.splitlines()[-1])
        assert proc.returncode == 4, err
        assert final["event"] == "aborted" and sig.name in final["message"]
        assert final["underruns"] == 0
        assert all(p["commanded"] == p["executed"] for p in final["pulses"].values())
        assert [c for c in children if running(c)] == []
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_closed_pipe_ends_without_a_traceback() -> None:
    shell = (f"{sys.executable} -m controller.operator.cli inspect "
             f"{REPO / 'nc_programs/naca2415.nc'} --json | head -c 10 > /dev/null")
    done = subprocess.run(["bash", "-o", "pipefail", "-c", shell], capture_output=True,
                          text=True, timeout=60)
    assert "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr


def test_an_oversized_config_is_refused_before_parsing(tmp_path: Path) -> None:
    big = tmp_path / "big.yaml"
    with big.open("w") as fh:
        fh.write("name: x\n")
        fh.write(("# " + "x" * 98 + "\n") * 20_000)  # 2 MB of comment
    t0 = time.monotonic()
    done = subprocess.run([*CNCCTL, "check", str(REPO / "nc_programs/arcs.nc"), "--config",
                           str(big)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "larger than 1048576 bytes" in done.stderr
    assert time.monotonic() - t0 < 10
    assert os.path.getsize(big) > 1 << 20


def test_an_embedded_run_pauses_at_m0_until_enter(tmp_path: Path) -> None:
    program = tmp_path / "m0.nc"
    program.write_text("G21 G90 G64 F2400\nG1 X10\nG1 Y10\nM0\nG1 X0\nG1 Y0\nM2\n")
    proc = subprocess.Popen([*CNCCTL, "run", str(program), "--json"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdin is not None
        while True:
            event = json.loads(proc.stdout.readline())
            if event["event"] == "progress" and event["state"] == "paused":
                break
            assert event["event"] in ("start", "progress"), event
        time.sleep(0.3)
        assert proc.poll() is None  # still waiting at the pause
        proc.stdin.write("\n")
        proc.stdin.flush()
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    final = json.loads(out.splitlines()[-1])
    assert proc.returncode == 0 and final["event"] == "done", err
    assert "paused at line 4 (M0)" in err
    assert final["final_position_mm"] == {"x": 0.0, "y": 0.0}
