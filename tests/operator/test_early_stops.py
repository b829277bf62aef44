"""Stops the operator asks before the motion starts, from outside (real processes, signals, a
pseudo-terminal, a real cncd): during homing, the check, --from-line's question, a jog."""

from __future__ import annotations

import json
import os
import pty
import select
import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml
from daemon_helpers import CNCCTL, REPO, running_cncd
from test_homing_jog import switches_config

ARCS = str(REPO / "nc_programs/arcs.nc")


@contextmanager
def _stopped_at_end(proc: subprocess.Popen) -> Iterator[subprocess.Popen]:
    """The process, killed by its pid at the end if it is still running (a failed test)."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _zigzag(path: Path, lines: int, at_mm: float) -> Path:
    """A long G1 program near (at_mm, at_mm): seconds to check, to read up to a line."""
    with path.open("w") as fh:
        fh.write("G21 G90 G64 F3000\n")
        for i in range(lines):
            fh.write(f"G1 X{at_mm + (i % 2) * 0.1:.1f} Y{at_mm + (i % 7) * 0.05:.2f}\n")
        fh.write("M2\n")
    return path


def _no_daemon(tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "CNCD_SOCKET": str(tmp_path / "none.sock")}


def _wait_for(proc: subprocess.Popen, needle: str, timeout_s: float = 30.0) -> str:
    """stderr lines until one holds needle (the process's stderr is a pipe)."""
    assert proc.stderr is not None
    seen = ""
    deadline = time.monotonic() + timeout_s
    while needle not in seen:
        assert time.monotonic() < deadline, seen
        line = proc.stderr.readline()
        assert line, seen
        seen += line
    return seen


def test_sigterm_while_homing_stops_the_homing_and_the_program_never_starts(
        tmp_path: Path) -> None:
    """SIGTERM 0.5 s into `run --home`: homing went on, then the whole program ran, exit 0."""
    data = yaml.safe_load(switches_config(tmp_path).read_text())
    data["drive"]["options"]["true_start_mm"] = [0.0, 0.0]  # 149 mm to go: seconds of search
    config = tmp_path / "far.yaml"
    config.write_text(yaml.safe_dump(data))
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G1 X-140 Y140 F1200\nM2\n")
    proc = subprocess.Popen([*CNCCTL, "run", str(program), "--config", str(config), "--home"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_no_daemon(tmp_path), stdin=subprocess.DEVNULL)
    with _stopped_at_end(proc):
        _wait_for(proc, "homing X, Y")
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 4, err
    assert "SIGTERM" in err and "while homing" in err and "did not start" in err
    assert "done" not in out


def test_sigterm_while_checking_before_a_confirmed_approach_moves_nothing(
        tmp_path: Path) -> None:
    """`--from-line N --yes` on a long program, SIGTERM while it reads up to line N: the
    abort was dropped when the runtime started, and approach and program ran (exit 0)."""
    program = _zigzag(tmp_path / "long.nc", 150_000, 10.0)
    proc = subprocess.Popen([*CNCCTL, "run", str(program), "--from-line", "140000", "--yes",
                             "--virtual-time", "--json"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_no_daemon(tmp_path),
                            stdin=subprocess.DEVNULL)
    with _stopped_at_end(proc):
        # The check is done and the stop signals are cncctl's once it announces the start;
        # then it reads 140,000 lines to find where the program stands (a sleep of 1 s fell
        # before the check's end on a loaded machine, where SIGTERM's default action killed it).
        assert proc.stdout is not None
        assert json.loads(proc.stdout.readline())["event"] == "start"
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    assert proc.returncode == 4, err
    final = json.loads(out.splitlines()[-1])
    assert final["event"] == "aborted" and "SIGTERM" in final["message"]
    assert final["final_position_mm"] == {"x": 0.0, "y": 0.0}  # nothing moved


def _question_on_a_pty(keys: bytes) -> tuple[int | None, str]:
    """`run arcs.nc --from-line 8` on a pseudo-terminal: keys typed once the question shows;
    (exit code or None if still running 20 s later, everything it wrote)."""
    pid, fd = pty.fork()
    if pid == 0:  # the child: cncctl on the terminal
        os.environ["CNCD_SOCKET"] = "/nonexistent/cncd.sock"
        os.execv(CNCCTL[0], [*CNCCTL, "run", ARCS, "--from-line", "8", "--virtual-time"])
    out = b""
    reaped = False
    try:
        deadline = time.monotonic() + 30
        while b"Ctrl-C to cancel" not in out:
            assert time.monotonic() < deadline, out
            if select.select([fd], [], [], 0.1)[0]:
                out += os.read(fd, 65536)
        os.write(fd, keys)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                reaped = True
                return os.waitstatus_to_exitcode(status), out.decode(errors="replace")
            if select.select([fd], [], [], 0.05)[0]:
                try:
                    out += os.read(fd, 65536)
                except OSError:
                    pass
        return None, out.decode(errors="replace")
    finally:
        if not reaped:  # still running, or the test failed on the way: stopped by its pid
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        os.close(fd)


def test_one_enter_on_a_terminal_confirms_the_approach() -> None:
    """The key reader took the first Enter (two or three were needed)."""
    code, out = _question_on_a_pty(b"\r")
    assert code == 0, out
    assert "done" in out


def test_ctrl_c_on_a_terminal_cancels_the_approach_and_nothing_moves() -> None:
    """Ctrl-C only asked for an abort nobody read: the question kept waiting, and an Enter
    after it ran the approach and reported success (exit 0)."""
    code, out = _question_on_a_pty(b"\x03\r\r")
    assert code == 2, out
    assert "not confirmed: nothing moved" in out and "done" not in out


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_at_the_question_cancels_it(tmp_path: Path, sig: signal.Signals) -> None:
    read, write = os.pipe()  # stdin kept open, nothing typed
    proc = subprocess.Popen([*CNCCTL, "run", ARCS, "--from-line", "8", "--virtual-time"],
                            stdin=read, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_no_daemon(tmp_path))
    os.close(read)
    try:
        with _stopped_at_end(proc):
            _wait_for(proc, "Ctrl-C to cancel")
            proc.send_signal(sig)
            _, err = proc.communicate(timeout=20)
    finally:
        os.close(write)
    assert proc.returncode == 2 and "nothing moved" in err


def test_cncd_does_not_approach_for_a_job_aborted_while_checking(tmp_path: Path) -> None:
    """An abort while a from-line job was CHECKING answered CHECKING, the client said
    aborted, and the daemon then made the approach move anyway."""
    program = _zigzag(tmp_path / "long.nc", 400_000, 20.0)
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        before = d.status()["position_mm"]
        run = subprocess.Popen([*CNCCTL, "run", str(program), "--from-line", "390000", "--yes",
                                "--socket", d.socket_path], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
        with _stopped_at_end(run):
            deadline = time.monotonic() + 20
            while d.status()["state"] != "CHECKING":
                assert time.monotonic() < deadline
                time.sleep(0.02)
            assert d.cncctl("abort").returncode == 0
            run.communicate(timeout=60)
        assert run.returncode == 4
        deadline = time.monotonic() + 20
        while d.status()["state"] != "IDLE":
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert d.status()["position_mm"] == before
        assert "approach to line" not in d.log_text()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_to_a_continuous_jog_client_stops_the_jog(
        tmp_path: Path, sig: signal.Signals) -> None:
    """The jog went on to its time-out or the soft limit when its terminal closed (SIGHUP)."""
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        read, write = os.pipe()
        jog = subprocess.Popen([*CNCCTL, "jog", "X+", "--feed", "600", "--timeout", "20",
                                "--socket", d.socket_path], stdin=read,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        os.close(read)
        try:
            with _stopped_at_end(jog):
                deadline = time.monotonic() + 20
                while d.status()["state"] != "RUNNING":
                    assert time.monotonic() < deadline
                    time.sleep(0.02)
                time.sleep(0.3)
                x_before_mm = d.status()["position_mm"]["x"]
                t_before_s = time.monotonic()
                jog.send_signal(sig)
                out, _ = jog.communicate(timeout=20)
        finally:
            os.close(write)
        deadline = time.monotonic() + 5
        while d.status()["state"] != "IDLE":
            assert time.monotonic() < deadline, "the jog is still moving"
            time.sleep(0.05)
        waited_s = time.monotonic() - t_before_s
        assert "aborted" in out, out
        # At most what 10 mm/s covers from the last reading before the signal to IDLE (each
        # status reading is a process of its own: slow on a loaded machine, so the bound is
        # taken from the clock, not assumed); the jog went on for 20 s before.
        assert d.status()["position_mm"]["x"] - x_before_mm <= 10.0 * waited_s + 0.5


def test_an_approach_stopped_is_journalled_under_its_program_and_line(tmp_path: Path) -> None:
    """The approach of a from-line job was written into the previous job's journal entry (a
    crash during it then read 'done'); the entry names the program and the line to give, and
    so does the status meanwhile (it showed the approach's line 2)."""
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        assert d.cncctl("jog", "X-5").returncode == 0  # a previous job to be mistaken for
        run = subprocess.Popen([*CNCCTL, "run", ARCS, "--from-line", "8", "--yes",
                                "--socket", d.socket_path], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
        with _stopped_at_end(run):
            deadline = time.monotonic() + 20
            while "approach to line 8" not in d.log_text():
                assert time.monotonic() < deadline
                time.sleep(0.02)
            time.sleep(0.2)
            assert d.status()["line"] == 8  # the line run from, not the approach's own
            assert d.cncctl("abort").returncode == 0
            run.communicate(timeout=30)
        journal = json.loads((d.state_dir / "journal.json").read_text())
        assert journal["program"].endswith("arcs.nc") and journal["last_line"] == 8
        assert journal["state"] == "ABORTED"


def test_a_crashed_daemons_job_files_are_removed_at_start(tmp_path: Path) -> None:
    from controller.operator.daemon.machine import LEFTOVER_PREFIXES
    from controller.operator.daemon.state_dir import StateDir
    job = tmp_path / "job-abc123"
    job.mkdir()
    (job / "program.nc").write_text("G1 X1\n")
    (tmp_path / "approach-xyz.nc").write_text("G1 X1\n")
    (tmp_path / "journal.json").write_text("{}")
    StateDir(tmp_path).remove_leftovers(LEFTOVER_PREFIXES)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["journal.json"]
