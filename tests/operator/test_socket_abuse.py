"""Whatever other clients do, e-stop, abort and status get through (real cncd, real sockets)."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path

import yaml
from daemon_helpers import REPO, running_cncd

from controller.operator.client import estop_socket_path


def _config(tmp_path: Path, max_connections: int) -> Path:
    data = yaml.safe_load((REPO / "config/xy_table.yaml").read_text())
    data["service"] = {"max_connections": max_connections}
    path = tmp_path / "machine.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _subscriber(path: str) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.connect(path)
    sock.sendall(b'{"id": 1, "cmd": "subscribe", "topics": ["state"]}\n')
    sock.settimeout(5.0)
    assert json.loads(sock.makefile("rb").readline())["ok"]
    return sock


def test_silent_subscribers_at_the_cap_lock_out_neither_estop_nor_status(tmp_path: Path) -> None:
    """16 subscribers that then say nothing fill a cap of 16: `estop` answered
    too-many-connections, then Broken pipe, for as long as they stayed."""
    with running_cncd(tmp_path, "--config", str(_config(tmp_path, 16))) as d:
        assert d.cncctl("reset").returncode == 0
        hogs = [_subscriber(d.socket_path) for _ in range(16)]
        try:
            status = d.cncctl("status", "--json")
            assert status.returncode == 0, status.stderr
            assert json.loads(status.stdout)["state"] == "IDLE"
            estop = d.cncctl("estop")
            assert estop.returncode == 0 and estop.stdout.strip() == "cncctl estop: ESTOP", \
                estop.stderr
            assert d.status()["state"] == "ESTOP"
        finally:
            for sock in hogs:
                sock.close()


def test_the_estop_socket_needs_no_request_and_no_slot(tmp_path: Path) -> None:
    with running_cncd(tmp_path, "--config", str(_config(tmp_path, 4))) as d:
        assert d.cncctl("reset").returncode == 0
        hogs = [_subscriber(d.socket_path) for _ in range(4)]
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                sock.settimeout(5.0)
                sock.connect(estop_socket_path(d.socket_path))  # nothing sent
                reply = json.loads(sock.makefile("rb").readline())
            assert reply == {"ok": True, "state": "ESTOP"}
            assert "e-stop socket" in d.log_text()
        finally:
            for sock in hogs:
                sock.close()


def test_a_trickled_request_times_out_whole(tmp_path: Path) -> None:
    """One byte every 0.5 s restarted the 10 s request time-out at each byte; the whole
    request must now be complete 10 s after its first byte."""
    with running_cncd(tmp_path) as d:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.connect(d.socket_path)
            sock.setblocking(False)
            t0 = time.monotonic()
            reply = b""
            while b"\n" not in reply and time.monotonic() - t0 < 25:
                try:
                    sock.send(b" ")
                except OSError:
                    break
                time.sleep(0.5)
                try:
                    reply += sock.recv(4096)
                except BlockingIOError:
                    pass
            took_s = time.monotonic() - t0
        assert b'"timeout"' in reply, reply
        assert 9.5 < took_s < 15.0


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


def test_programs_being_sent_are_bounded_in_total_and_kept_out_of_memory(tmp_path: Path
                                                                         ) -> None:
    """Two 64 MiB programs may arrive at once, not a third; what arrives is spooled to a
    file (16 trickled programs held 1.36 GB of the daemon's locked memory)."""
    size = 64 * 1024 * 1024
    with running_cncd(tmp_path) as d:
        assert d.cncctl("reset").returncode == 0
        rss0_mb = _rss_mb(d.proc.pid)
        senders = []
        try:
            for _ in range(2):
                sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                sock.connect(d.socket_path)
                sock.sendall(json.dumps({"id": 1, "cmd": "run", "name": "big.nc",
                                         "program_bytes": size}).encode() + b"\n")
                chunk = b"(" + b"x" * ((1 << 20) - 3) + b")\n"
                for _ in range(48):  # 48 MiB each, the rest never comes
                    sock.sendall(chunk)
                senders.append(sock)
            time.sleep(0.5)
            third = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            third.connect(d.socket_path)
            third.settimeout(5.0)
            third.sendall(json.dumps({"id": 7, "cmd": "run", "name": "c.nc",
                                      "program_bytes": 1000}).encode() + b"\n")
            reply = json.loads(third.makefile("rb").readline())
            third.close()
            assert reply["ok"] is False and reply["error"] == "busy", reply
            assert "at most at once" in reply["message"]
            assert _rss_mb(d.proc.pid) - rss0_mb < 40, (rss0_mb, _rss_mb(d.proc.pid))
        finally:
            for sock in senders:
                sock.close()


def test_abort_during_a_long_check_ends_it_at_once_and_status_answers_meanwhile(
        tmp_path: Path) -> None:
    """The check ran in the daemon's job thread: a 60 MB comment-only program withheld the
    watchdog for 4 s, and an abort answered ok while the job stayed CHECKING for 21 s."""
    from daemon_helpers import raw, start_run

    program = tmp_path / "comments.nc"
    with program.open("w") as fh:
        fh.write("G21 G90\n")
        line = "(" + "x" * 70 + ")\n"
        for _ in range(800_000):  # 58 MB of comments: seconds of check
            fh.write(line)
        fh.write("G1 X1 F600\nM2\n")
    with running_cncd(tmp_path) as d:
        assert d.cncctl("reset").returncode == 0
        run = start_run(d, program)
        try:
            deadline = time.monotonic() + 60
            while d.status()["state"] != "CHECKING":
                assert time.monotonic() < deadline and run.poll() is None
                time.sleep(0.02)
            t0 = time.monotonic()
            status = raw(d.socket_path, b'{"id": 1, "cmd": "status"}\n')  # not stalled
            assert status[0]["state"] == "CHECKING"
            assert raw(d.socket_path, b'{"id": 2, "cmd": "abort"}\n')[0]["ok"]
            while d.status()["state"] != "IDLE":
                assert time.monotonic() - t0 < 5.0, "the check went on after the abort"
                time.sleep(0.02)
            out, err = run.communicate(timeout=30)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait()
        assert run.returncode == 4 and "aborted" in out + err, (out, err)
        assert d.status()["position_mm"] == {"x": 0.0, "y": 0.0}


def test_small_ones_duplicate_keys_follow_fields_resume_after_estop_rejected_then_idle(
        tmp_path: Path) -> None:
    """{"cmd": "status", "cmd": "estop"} ran an e-stop; follow was not checked; resume right
    after estop answered RUNNING; the rejected event came before the machine was IDLE."""
    from daemon_helpers import raw

    bad = tmp_path / "bad.nc"
    bad.write_text("G21 G90\nG1 X1 F600 Q7\nM2\n")
    with running_cncd(tmp_path) as d:
        assert d.cncctl("reset").returncode == 0
        reply = raw(d.socket_path, b'{"id": 1, "cmd": "status", "cmd": "estop"}\n')[0]
        assert reply["ok"] is False and reply["error"] == "malformed"
        assert d.status()["state"] == "IDLE"
        reply = raw(d.socket_path, b'{"id": 2, "cmd": "log", "follow": "yes"}\n')[0]
        assert reply["ok"] is False and "follow must be true or false" in reply["message"]
        for _ in range(5):  # each rejection leaves the machine IDLE before it is told
            done = d.cncctl("run", str(bad))
            assert done.returncode == 2 and "busy" not in done.stderr, done.stderr


def test_resume_right_after_an_estop_is_refused(tmp_path: Path) -> None:
    from daemon_helpers import start_run, wait_moving

    program = tmp_path / "square.nc"
    program.write_text("G21 G90 G64 F1200\nG1 X40\nG1 Y10\nG1 X0\nG1 Y0\nM2\n")
    with running_cncd(tmp_path) as d:
        assert d.cncctl("reset").returncode == 0
        run = start_run(d, program)
        try:
            wait_moving(run, after_s=0.3)
            assert d.cncctl("hold").returncode == 0
            assert d.cncctl("estop").returncode == 0
            resume = d.cncctl("resume")
            # Refused either way: while the e-stop's stop runs ("stopping"), or after it.
            refused = "stopping" in resume.stderr or "not-paused" in resume.stderr
            assert resume.returncode == 2 and refused, (resume.stdout, resume.stderr)
            run.communicate(timeout=30)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait()
        assert d.status()["state"] == "ESTOP"


_FLOOD = """
import socket, sys, threading
def flood():
    while True:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            s.connect(sys.argv[1])
            s.sendall(b'{"id": 1, "cmd": "status"}\\n')
        except OSError:
            pass
        s.close()
for _ in range(4):
    threading.Thread(target=flood, daemon=True).start()
print("flooding", flush=True)
threading.Event().wait()
"""


def test_a_process_flooding_the_socket_is_turned_away_and_others_get_through(
        tmp_path: Path) -> None:
    """4 threads connecting, asking status and hanging up as fast as they could kept the listen
    queue full: `cncctl reset` and 14 of 20 status requests failed at once with EAGAIN."""
    import subprocess
    import sys

    with running_cncd(tmp_path) as d:
        assert d.cncctl("reset").returncode == 0
        flood = subprocess.Popen([sys.executable, "-c", _FLOOD, d.socket_path],
                                 stdout=subprocess.PIPE, text=True)
        try:
            assert flood.stdout is not None and flood.stdout.readline() == "flooding\n"
            time.sleep(1.0)
            for _ in range(3):
                status = d.cncctl("status", "--json")
                assert status.returncode == 0, status.stderr
                assert d.cncctl("reset").returncode == 0
            estop = d.cncctl("estop")
            assert estop.returncode == 0, estop.stderr
        finally:
            flood.kill()
            flood.wait()
        assert d.status()["state"] == "ESTOP"
        assert f"pid {flood.pid} " in d.log_text() and "connects more than" in d.log_text()
