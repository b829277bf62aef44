"""Helpers for the cncd tests: a daemon in the foreground with a fake systemd notify socket,
stopped by its pid whatever happens; raw socket requests; process and shared-memory probes."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
CNCCTL = [sys.executable, "-m", "controller.operator.cli"]
CNCD = [sys.executable, "-m", "controller.operator.daemon.main"]
# Drive options for a run on a peer whose test is not about the link: a 2-core machine running
# the suite's other workers (or two CPU hogs) stalls a pty or the SYNC thread for more than the
# defaults (serial 100 ms, CANopen heartbeats 300 ms, TPDOs 100 SYNCs) at times; the link
# tests keep those.
LOADED_CANOPEN = {"heartbeat_timeout_ms": 1000, "sdo_timeout_s": 1.0, "tpdo_timeout_cycles": 500}
LOADED_LINK = {"serial": ["--drive-option", "link_timeout_s=0.5"],
               "canopen": [arg for key, value in LOADED_CANOPEN.items()
                           for arg in ("--drive-option", f"{key}={value}")]}


@dataclass
class NotifyLog:
    """A fake systemd manager: records every notify datagram with its arrival time."""

    sock: socket.socket
    messages: list[tuple[float, str]] = field(default_factory=list)

    def drain(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096)
            except OSError:
                return
            self.messages.append((time.monotonic(), data.decode()))

    def seen(self, text: str) -> bool:
        return any(text in m for _, m in self.messages)

    def wait_for(self, text: str, timeout_s: float = 20.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not self.seen(text):
            assert time.monotonic() < deadline, f"no {text!r} notification in {timeout_s} s"
            time.sleep(0.01)

    def times(self, text: str) -> list[float]:
        return [t for t, m in self.messages if text in m]


@dataclass
class Cncd:
    proc: subprocess.Popen
    socket_path: str
    state_dir: Path
    notify: NotifyLog
    stderr_path: Path

    def cncctl(self, *words: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
        return subprocess.run([*CNCCTL, *words, "--socket", self.socket_path],
                              capture_output=True, text=True, timeout=timeout_s)

    def status(self) -> dict[str, Any]:
        done = self.cncctl("status", "--json")
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout)

    def log_text(self) -> str:
        return self.stderr_path.read_text()


def start_cncd(tmp_path: Path, *extra: str, env: dict[str, str] | None = None,
               preexec: Any = None, name: str = "cncd", wrapper: list[str] | None = None
               ) -> Cncd:
    """wrapper: a command that execs the daemon (setpriv ...): the pid stays the daemon's."""
    notify_path = str(tmp_path / f"{name}-notify")
    manager = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    if os.path.exists(notify_path):
        os.unlink(notify_path)  # a daemon started again in the same directory (a restart)
    manager.bind(notify_path)
    notify = NotifyLog(manager)
    threading.Thread(target=notify.drain, daemon=True).start()
    socket_path = str(tmp_path / f"{name}.sock")
    state_dir = tmp_path / f"{name}-state"
    stderr_path = tmp_path / f"{name}.log"
    full_env = {**os.environ, "NOTIFY_SOCKET": notify_path, "WATCHDOG_USEC": "1000000",
                **(env or {})}
    with stderr_path.open("w") as err:
        proc = subprocess.Popen([*(wrapper or []), *CNCD, "--socket", socket_path,
                                 "--state-dir", str(state_dir), *extra], stderr=err,
                                env=full_env, preexec_fn=preexec)
    daemon = Cncd(proc, socket_path, state_dir, notify, stderr_path)
    try:
        notify.wait_for("READY=1")
    except AssertionError:
        stop(daemon)
        raise AssertionError(f"cncd did not become ready: {stderr_path.read_text()}") from None
    return daemon


def stop(daemon: Cncd) -> None:
    """Always by pid: SIGKILL if it is still there, then reap it."""
    if daemon.proc.poll() is None:
        daemon.proc.send_signal(signal.SIGKILL)
    daemon.proc.wait(timeout=10)
    daemon.notify.sock.close()


@contextmanager
def running_cncd(tmp_path: Path, *extra: str, **kw: Any) -> Iterator[Cncd]:
    daemon = start_cncd(tmp_path, *extra, **kw)
    try:
        yield daemon
    finally:
        stop(daemon)


def raw(path: str, data: bytes, timeout_s: float = 5.0) -> list[dict[str, Any]]:
    """Send bytes, read replies until the daemon has answered and gone quiet or hung up."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout_s)
        s.connect(path)
        try:
            s.sendall(data)
        except OSError:
            pass  # the daemon may hang up on an oversized request before reading all of it
        return _read_replies(s)


def _read_replies(s: socket.socket) -> list[dict[str, Any]]:
    buf = b""
    s.settimeout(1.0)
    while True:
        try:
            chunk = s.recv(65536)
        except (TimeoutError, ConnectionResetError):
            break
        if not chunk:
            break
        buf += chunk
    return [json.loads(line) for line in buf.splitlines() if line.strip()]


def children_of(pid: int) -> list[int]:
    kids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[1]) == pid and fields[0] not in ("Z", "X"):
                kids.append(int(entry.name))
    return kids


def running(pid: int, wait_s: float = 3.0) -> bool:
    """Still running after wait_s (an exited process awaiting its reaper does not count)."""
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            return False
        if state in ("Z", "X"):
            return False
        time.sleep(0.02)
    return True


def shm_names() -> set[str]:
    return set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()


def start_run(daemon: Cncd, program: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([*CNCCTL, "run", str(program), "--json", "--socket",
                             daemon.socket_path, *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)


def wait_moving(run: subprocess.Popen, after_s: float = 0.1) -> None:
    assert run.stdout is not None
    seen: list[dict[str, Any]] = []  # the events other than progress, shown if it ends
    while True:
        line = run.stdout.readline()
        assert line, (f"the run ended before moving: {run.stderr.read() if run.stderr else ''}"
                      f" (exit {run.wait()}; events {seen[-5:]})")
        event = json.loads(line)
        if event["event"] == "progress" and event.get("executed_s", 0) > after_s:
            return
        if event["event"] != "progress":
            seen.append(event)


def run_confirming_tools(args: list[str]) -> list[dict[str, Any]]:
    """`cncctl run --json` answering each manual tool change with Enter; its events but the
    progress reports. The process is stopped by its pid if it outlives the reading."""
    proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=REPO)
    events = []
    try:
        assert proc.stdout is not None and proc.stdin is not None
        for line in proc.stdout:
            event = json.loads(line)
            if event["event"] != "progress":
                events.append(event)
            if event["event"] == "tool":
                proc.stdin.write("\n")
                proc.stdin.flush()
        assert proc.wait(timeout=60) == 0, (events[-1], proc.stderr.read() if proc.stderr else "")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return events


def open_switch(path: Path, name: str) -> None:
    """Trip the limit switch `name` ("y-") of a drive's limit_input_file: written whole, then
    renamed, since the drive reads a file that exists but is still empty as X- (an input
    whose name cannot be read is still open)."""
    part = path.with_name(path.name + ".part")
    part.write_text(f"{name}\n")
    os.replace(part, path)
