"""Feed hold, resume and override from outside: through cncd's socket, and by key on a pty."""

from __future__ import annotations

import json
import os
import pty
import select
import subprocess
import time
from pathlib import Path

from daemon_helpers import CNCCTL, running_cncd, start_run, wait_moving

SQUARE = "G21 G90 G64 F1200\nG1 X40\nG1 Y10\nG1 X0\nG1 Y0\nM2\n"  # 5 s at 20 mm/s


def wait_state(d, state: str | tuple[str, ...], timeout_s: float = 20.0) -> dict:
    states = (state,) if isinstance(state, str) else state
    deadline = time.monotonic() + timeout_s
    while True:
        status = d.status()
        if status["state"] in states:
            return status
        assert time.monotonic() < deadline, f"never {state}: {status}"
        time.sleep(0.05)


def test_hold_resume_and_feed_through_the_daemon(tmp_path: Path) -> None:
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        assert d.cncctl("hold").returncode == 2  # no job: refused
        assert d.cncctl("feed", "151").returncode == 2  # out of range: refused
        run = start_run(d, program)
        try:
            wait_moving(run, after_s=0.5)
            hold = d.cncctl("hold")
            assert hold.returncode == 0 and hold.stdout.strip() == "cncctl hold: HOLDING"
            held = wait_state(d, "HELD")
            assert d.cncctl("hold").stdout.strip() == "cncctl hold: HELD"
            time.sleep(0.3)
            again = d.status()
            assert again["state"] == "HELD" and again["position_mm"] == held["position_mm"]
            x, y = held["position_mm"]["x"], held["position_mm"]["y"]
            # held on the square (the first side on a quiet machine; under load the hold may
            # come later), within its corner blends, and before its end
            assert _from_square_mm(x, y) <= 0.05 and (x, y) != (0.0, 0.0)
            assert d.cncctl("feed", "50").returncode == 0
            assert d.status()["feed_override_pct"] == 50.0
            time.sleep(0.2)
            assert d.cncctl("feed", "0").returncode == 0
            resume = d.cncctl("resume")  # resumed, but 0 % keeps it where it is: said so
            assert resume.returncode == 0 and resume.stdout.startswith(
                "cncctl resume: HELD (the feed override is 0 %")
            time.sleep(0.3)
            assert d.status()["position_mm"] == held["position_mm"]
            assert d.cncctl("feed", "100").returncode == 0
            # Moving again; under load the hold may come near the end, and what is left of the
            # square can be done before the first status after `cncctl feed` returns.
            moving = wait_state(d, ("RUNNING", "IDLE"))
            assert moving["state"] == "RUNNING" or moving["last_job"]["state"] == "DONE"
            out, err = run.communicate(timeout=30)
        finally:
            run.kill()
        events = [json.loads(line) for line in out.splitlines()]
        final = events[-1]
        assert run.returncode == 0 and final["event"] == "done", err
        assert final["final_position_mm"] == {"x": 0.0, "y": 0.0} and final["underruns"] == 0
        assert final["contour_error_um"]["max"] <= 30.0
        states = {e["state"] for e in events if e["event"] == "progress"}
        assert "held" in states
        assert "feed hold" in d.log_text() and "feed override 50 %" in d.log_text()


def _from_square_mm(x: float, y: float) -> float:
    """Distance from the square's sides (0,0)-(40,0)-(40,10)-(0,10)-(0,0)."""
    dx = max(0.0 - x, 0.0, x - 40.0)
    dy = max(0.0 - y, 0.0, y - 10.0)
    outside = (dx * dx + dy * dy) ** 0.5
    return outside if outside > 0.0 else min(x, 40.0 - x, y, 10.0 - y)


def _read_until(fd: int, needle: bytes, timeout_s: float = 20.0) -> bytes:
    seen = b""
    deadline = time.monotonic() + timeout_s
    while needle not in seen:
        left = deadline - time.monotonic()
        assert left > 0, f"no {needle!r} in {seen[-2000:]!r}"
        ready, _, _ = select.select([fd], [], [], left)
        if ready:
            try:
                chunk = os.read(fd, 65536)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
    assert needle in seen, f"the run ended without {needle!r}: {seen[-2000:]!r}"
    return seen


def test_space_bar_holds_and_resumes_an_embedded_run(tmp_path: Path) -> None:
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    main, sub = pty.openpty()
    env = {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}  # embedded, no daemon
    proc = subprocess.Popen([*CNCCTL, "run", str(program), "--json"], stdin=sub, stdout=sub,
                            stderr=sub, env=env, close_fds=True)
    os.close(sub)
    try:
        _read_until(main, b'"state": "running"')
        time.sleep(0.5)
        os.write(main, b" ")
        text = _read_until(main, b"held at line")
        _read_until(main, b'"state": "held"')
        os.write(main, b"-")  # 90 %
        os.write(main, b" ")
        text += _read_until(main, b'"event": "done"', timeout_s=30)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(main)
    assert proc.returncode == 0
    assert b"feed override 90 %" in text
    final = json.loads(text[text.rindex(b'{"event": "done"'):].splitlines()[0])
    assert final["final_position_mm"] == {"x": 0.0, "y": 0.0} and final["underruns"] == 0


M1_PROGRAM = "G21 G90 G64 F2400\nG1 X10\nM1\nG1 Y10\nM2\n"


def _run_m1(tmp_path: Path, *extra: str, stdin: bytes = b"") -> tuple[int, list[dict], str]:
    program = tmp_path / "m1.nc"
    program.write_text(M1_PROGRAM)
    env = {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}
    proc = subprocess.Popen([*CNCCTL, "run", str(program), "--json", "--virtual-time", *extra],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env)
    try:
        assert proc.stderr is not None and proc.stdin is not None
        if stdin:
            err = b""
            while b"paused at line 3" not in err:  # wait for the pause, then press Enter
                chunk = proc.stderr.readline()
                assert chunk, "the run ended without pausing"
                err += chunk
            proc.stdin.write(stdin)
            proc.stdin.flush()
        out, rest = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    events = [json.loads(line) for line in out.splitlines()]
    return proc.returncode, events, (err if stdin else b"").decode() + rest.decode()


def test_m1_is_skipped_unless_optional_stop_is_on(tmp_path: Path) -> None:
    code, events, _ = _run_m1(tmp_path)
    assert code == 0 and not any(e.get("state") == "paused" for e in events)
    code, events, err = _run_m1(tmp_path, "--optional-stop", stdin=b"\n")
    assert code == 0 and "paused at line 3 (M0)" in err.replace("(M1)", "(M0)")
    assert events[-1]["event"] == "done"
    assert events[-1]["final_position_mm"] == {"x": 10.0, "y": 10.0}
