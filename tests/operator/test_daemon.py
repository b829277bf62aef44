"""cncd end to end, from outside: a real daemon process, its real socket, a fake systemd."""

from __future__ import annotations

import json
import os
import signal
import socket
import stat
import time
from pathlib import Path

from daemon_helpers import (
    REPO,
    children_of,
    raw,
    running,
    running_cncd,
    shm_names,
    start_cncd,
    start_run,
    stop,
    wait_moving,
)

AIRFOIL = REPO / "nc_programs/naca2415.nc"
LONG = REPO / "nc_programs/butterfly.nc"  # 7 s of motion: time to act mid-run


def test_ready_watchdog_run_status_and_sigterm(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        assert d.status()["state"] == "ESTOP"  # never moves by itself after a start
        refused = d.cncctl("run", str(AIRFOIL))
        assert refused.returncode == 2 and "estop" in refused.stderr
        assert d.cncctl("reset").returncode == 0
        done = d.cncctl("run", str(AIRFOIL), "--json")
        assert done.returncode == 0, done.stderr
        final = json.loads(done.stdout.splitlines()[-1])
        assert final["event"] == "done" and final["underruns"] == 0
        assert final["final_position_mm"] == {"x": 0.0, "y": 0.001}
        status = d.status()
        assert status["state"] == "IDLE" and status["last_job"]["state"] == "DONE"
        assert status["last_job"]["program"] == str(AIRFOIL)
        assert len(d.notify.times("WATCHDOG=1")) >= 2
        d.proc.send_signal(signal.SIGTERM)
        assert d.proc.wait(timeout=20) == 0
        assert d.notify.seen("STOPPING=1") and not os.path.exists(d.socket_path)


def test_abort_stops_along_the_path_and_a_second_run_is_refused(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, LONG)
        try:
            wait_moving(run)
            second = d.cncctl("run", str(AIRFOIL))
            assert second.returncode == 2 and "busy" in second.stderr  # refused, not queued
            assert d.cncctl("abort").returncode == 0
            out, _ = run.communicate(timeout=20)
        finally:
            run.kill()
        final = json.loads(out.splitlines()[-1])
        assert run.returncode == 4 and final["event"] == "aborted"
        assert final["underruns"] == 0
        assert all(p["commanded"] == p["executed"] for p in final["pulses"].values())
        time.sleep(1.0)  # nothing starts moving after the abort (the refused job was dropped)
        status = d.status()
        assert status["state"] == "IDLE" and status["job"] is None
        assert "job 2" not in d.log_text()


def test_sigterm_mid_run_stops_under_control_and_exits_0(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, LONG)
        try:
            wait_moving(run)
            kids = children_of(d.proc.pid)
            t0 = time.monotonic()
            d.proc.send_signal(signal.SIGTERM)
            assert d.proc.wait(timeout=20) == 0
            stop_s = time.monotonic() - t0
            out, _ = run.communicate(timeout=10)
        finally:
            run.kill()
        final = json.loads(out.splitlines()[-1])
        assert final["event"] == "aborted" and "SIGTERM" in final["message"]
        assert all(p["commanded"] == p["executed"] for p in final["pulses"].values())
        assert stop_s < 5.0
        assert [k for k in kids if running(k)] == []


def test_the_daemon_never_opens_a_path_a_client_names(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        replies = raw(d.socket_path, b'{"id": 1, "cmd": "run", "program": "/etc/shadow"}\n')
        assert replies[0]["ok"] is False and replies[0]["error"] == "bad-field"
        assert "shadow" not in json.dumps(replies)  # no oracle, no echo
        # The name is only a label: errors are about the text that was sent.
        text = b"G1 X\n"
        replies = raw(d.socket_path, json.dumps({"id": 2, "cmd": "run", "name": "/etc/shadow",
                                                 "program_bytes": len(text)}).encode()
                      + b"\n" + text)
        assert replies[0]["ok"] is True
        assert replies[-1]["event"] == "rejected"
        assert replies[-1]["message"] == "/etc/shadow:1:4: error: X word without a number"


def test_socket_is_0660_whatever_the_umask(tmp_path: Path) -> None:
    with running_cncd(tmp_path, preexec=lambda: os.umask(0)) as d:
        mode = stat.S_IMODE(os.stat(d.socket_path).st_mode)
        assert mode == 0o660


def test_bad_requests_get_an_error_and_leave_the_daemon_serving(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        assert raw(d.socket_path, b"\x00\xffgarbage\n")[0]["error"] == "malformed"
        assert raw(d.socket_path, b"[1, 2, 3]\n")[0]["error"] == "malformed"
        assert raw(d.socket_path, b'{"cmd": "rm -rf"}\n')[0]["error"] == "unknown-command"
        assert raw(d.socket_path, b'{"cmd": "status", "x": 1}\n')[0]["error"] == "bad-field"
        assert raw(d.socket_path, b'{"cmd": "stat') == []  # truncated, then hung up
        big = raw(d.socket_path, b"x" * (100 << 20) + b"\n", timeout_s=30)
        assert big[0]["error"] == "too-large" and len(json.dumps(big)) < 300  # no echo
        too_big_program = b'{"cmd": "run", "program_bytes": 100000000}\n'
        assert raw(d.socket_path, too_big_program)[0]["error"] == "too-large"
        # ... and the daemon is unaffected.
        t0 = time.monotonic()
        assert raw(d.socket_path, b'{"id": 7, "cmd": "status"}\n')[0]["state"] == "ESTOP"
        assert time.monotonic() - t0 < 1.5
        assert d.proc.poll() is None


def test_300_idle_connections_then_status_within_100_ms(tmp_path: Path) -> None:
    import resource

    def low_fd_limit() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (256, 256))  # as in the report
    with running_cncd(tmp_path, preexec=low_fd_limit) as d:
        idle = []
        try:
            for _ in range(300):
                s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                s.connect(d.socket_path)
                idle.append(s)
            time.sleep(0.5)
            best = min(_status_time_s(d.socket_path) for _ in range(5))
            assert best < 0.1
        finally:
            for s in idle:
                s.close()
        assert _status_time_s(d.socket_path) < 0.1
        assert d.notify.times("WATCHDOG=1")[-1] > time.monotonic() - 1.5  # still healthy


def _status_time_s(path: str) -> float:
    """Connect, ask, and read the one reply line: the latency a client sees."""
    t0 = time.monotonic()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5.0)
        s.connect(path)
        s.sendall(b'{"id": 1, "cmd": "status"}\n')
        reply = s.makefile("rb").readline()
    assert json.loads(reply)["ok"] is True, reply
    return time.monotonic() - t0


def test_a_client_of_another_uid_is_refused(tmp_path: Path) -> None:
    if os.geteuid() != 0:
        import pytest
        pytest.skip("needs root to switch to another uid")
    import shutil
    import tempfile

    public = Path(tempfile.mkdtemp(prefix="cncd-uid-"))  # pytest's tmp_path is 0700 all up
    public.chmod(0o755)
    try:
        _refuse_other_uid(public)
    finally:
        shutil.rmtree(public, ignore_errors=True)


def _refuse_other_uid(public: Path) -> None:
    with running_cncd(public) as d:
        os.chmod(d.socket_path, 0o666)  # let the file mode through: the peer check must refuse
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: nobody, no groups
            try:
                os.setgroups([])
                os.setgid(65534)
                os.setuid(65534)
                reply = raw(d.socket_path, b'{"id": 1, "cmd": "status"}\n')
                os.write(w, json.dumps(reply).encode())
            finally:
                os._exit(0)
        os.close(w)
        with os.fdopen(r) as fh:
            reply = json.loads(fh.read() or "[]")
        os.waitpid(pid, 0)
        assert reply and reply[0]["error"] == "unauthorised"
        assert "refused uid 65534" in d.log_text()


def test_sigkill_of_cncd_leaves_no_orphan_nor_shared_memory(tmp_path: Path) -> None:
    before = shm_names()
    d = start_cncd(tmp_path)
    try:
        d.cncctl("reset")
        run = start_run(d, LONG)
        wait_moving(run, after_s=0.3)
        time.sleep(0.2)  # the journal names the line within 0.05 s of the first progress
        kids = children_of(d.proc.pid)
        assert kids  # the generator at least (the interpreter may have finished)
        d.proc.send_signal(signal.SIGKILL)
        d.proc.wait(timeout=10)
        run.communicate(timeout=10)
        assert [k for k in kids if running(k)] == []
        deadline = time.monotonic() + 5
        while shm_names() - before and time.monotonic() < deadline:
            time.sleep(0.05)
        assert shm_names() - before == set()
    finally:
        stop(d)
    # A restart comes up in ESTOP and the journal names where the job was.
    restarted = start_cncd(tmp_path, "--state-dir", str(d.state_dir), name="cncd3")
    try:
        status = restarted.status()
        assert status["state"] == "ESTOP"
        assert status["last_job"]["state"] == "INTERRUPTED"
        assert status["last_job"]["program"] == str(LONG) and status["last_job"]["last_line"] > 0
    finally:
        stop(restarted)


def _long_program(tmp_path: Path) -> Path:
    """200 s of slow squares: the generator and interpreter are still working when killed."""
    program = tmp_path / "squares.nc"
    moves = "".join(f"G1 X{x} Y{y}\n" for _ in range(500) for x, y in
                    ((1, 0), (1, 1), (0, 1), (0, 0)))
    program.write_text("G21 G90 G64 F600\n" + moves + "M2\n")
    return program


def _producers(pid: int) -> list[int]:
    """The interpreter and generator processes of a running job (not multiprocessing's own
    resource tracker), generator first (it is started first)."""
    return sorted(k for k in children_of(pid)
                  if b"resource_tracker" not in Path(f"/proc/{k}/cmdline").read_bytes())


def test_sigkill_of_a_child_faults_the_job_and_the_daemon_serves_on(tmp_path: Path) -> None:
    program = _long_program(tmp_path)
    with running_cncd(tmp_path) as d:
        for victim in ("generator", "interpreter"):
            assert d.cncctl("reset").returncode == 0
            run = start_run(d, program)
            try:
                wait_moving(run)
                producers = _producers(d.proc.pid)
                assert len(producers) == 2, producers
                os.kill(producers[0 if victim == "generator" else 1], signal.SIGKILL)
                out, _ = run.communicate(timeout=20)
            finally:
                run.kill()
            final = json.loads(out.splitlines()[-1])
            assert run.returncode == 3 and final["event"] == "fault", final
            assert "died" in final["message"] or "failed" in final["message"], final
            assert final["position_known"] and final["underruns"] == 0
            assert d.proc.poll() is None
            status = d.status()
            assert status["state"] == "FAULT" and status["job"] is None
            assert [k for k in producers if running(k)] == []


def test_a_long_check_keeps_the_watchdog_fed(tmp_path: Path) -> None:
    program = tmp_path / "long.nc"
    with program.open("w") as fh:
        fh.write("G21 G90 F3000\n")
        for i in range(400_000):
            fh.write(f"G1 X{(i % 200) * 0.1:.1f} Y{(i % 7) * 0.1:.1f}\n")
    with running_cncd(tmp_path, env={"WATCHDOG_USEC": "600000"}) as d:
        d.cncctl("reset")
        run = start_run(d, program)
        try:
            deadline = time.monotonic() + 30
            while d.status()["state"] == "CHECKING" or d.status()["state"] == "IDLE":
                assert time.monotonic() < deadline
                time.sleep(0.1)
            d.cncctl("abort")
            run.communicate(timeout=30)
        finally:
            run.kill()
        pings = d.notify.times("WATCHDOG=1")
        gaps = [b - a for a, b in zip(pings, pings[1:], strict=False)]
        assert max(gaps) < 0.6, gaps  # pinged every 0.3 s all through the check


def test_a_client_that_hangs_up_mid_run_does_not_stop_the_daemon(tmp_path: Path) -> None:
    program = tmp_path / "loops.nc"  # ends where it starts, so it can run twice in a row
    moves = "".join(f"G1 X{x} Y{y}\n" for _ in range(12) for x, y in
                    ((1, 0), (1, 1), (0, 1), (0, 0)))
    program.write_text("G21 G90 G64 F1200\n" + moves + "M2\n")
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, program)
        wait_moving(run)
        run.kill()  # the client dies; the job is the machine's, it goes on to its end
        run.wait()
        deadline = time.monotonic() + 20
        while d.status()["state"] != "IDLE":
            assert time.monotonic() < deadline and d.proc.poll() is None
            time.sleep(0.1)
        assert d.status()["last_job"]["state"] == "DONE"
        assert d.cncctl("run", str(program)).returncode == 0  # and it serves the next one


def test_a_run_is_not_evicted_by_a_flood_of_idle_connections(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, AIRFOIL)
        flood = []
        try:
            wait_moving(run)
            for _ in range(200):  # far over the cap of 64: idle ones make room, not the run
                s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                s.connect(d.socket_path)
                flood.append(s)
            out, _ = run.communicate(timeout=30)
        finally:
            run.kill()
            for s in flood:
                s.close()
        assert run.returncode == 0 and json.loads(out.splitlines()[-1])["event"] == "done"


def test_m0_pauses_the_job_until_resume(tmp_path: Path) -> None:
    program = tmp_path / "m0.nc"
    program.write_text("G21 G90 G64 F2400\nG1 X10\nG1 Y10\nM0\nG1 X0\nG1 Y0\nM2\n")
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        assert d.cncctl("resume").returncode == 2  # nothing paused
        run = start_run(d, program)
        try:
            deadline = time.monotonic() + 20
            while d.status()["state"] != "PAUSED":
                assert time.monotonic() < deadline and run.poll() is None
                time.sleep(0.05)
            status = d.status()
            assert status["line"] == 4 and status["position_mm"] == {"x": 10.0, "y": 10.0}
            time.sleep(0.3)
            assert d.status()["state"] == "PAUSED"  # it waits, it does not go on by itself
            assert d.cncctl("resume").returncode == 0
            out, _ = run.communicate(timeout=20)
        finally:
            run.kill()
        final = json.loads(out.splitlines()[-1])
        assert run.returncode == 0 and final["event"] == "done"
        assert final["final_position_mm"] == {"x": 0.0, "y": 0.0} and final["underruns"] == 0


def test_a_request_that_once_killed_the_daemon_leaves_the_job_running(tmp_path: Path) -> None:
    poison = b'{"cmd": "feed", "percent": ' + b"9" * 5000 + b"}\n"  # over the 4300-digit limit
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        run = start_run(d, AIRFOIL)
        try:
            wait_moving(run)
            assert raw(d.socket_path, poison)[0]["error"] == "malformed"
            assert raw(d.socket_path, b'{"cmd": "status", "id": [1]}\n')[0]["error"] \
                == "bad-field"
            out, _ = run.communicate(timeout=30)
        finally:
            run.kill()
        assert run.returncode == 0 and json.loads(out.splitlines()[-1])["event"] == "done"
        assert d.proc.poll() is None and d.status()["state"] == "IDLE"
