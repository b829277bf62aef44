"""The OPC UA server as a child of cncd: started once the control socket listens, started again
if it dies, stopped by its pid when cncd stops. A process of its own, a client of the socket:
the motion loop and the socket's loop carry no OPC UA work and no asyncio, and a fault in the
server cannot reach the machine."""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import Any

from controller.config import MachineConfig
from controller.errors import CncError
from controller.operator.daemon.log import ERR, NOTICE, EventLog

# A job reports its progress this often with OPC UA on (0.1 s otherwise): a value's age at a
# subscriber is this period plus the delivery, and the companion model asks for 100 ms.
PROGRESS_EVERY_S = 0.05
STOP_WAIT_S = 5.0  # SIGTERM, then SIGKILL after this
RESTART_AFTER_S = (1.0, 2.0, 5.0, 10.0, 30.0)  # after its 1st, 2nd, ... unexpected exit


class OpcuaUnavailable(CncError):
    """service.opcua is set and the server cannot run: the extra is missing, or the users
    file cannot be trusted."""


def require_opcua(config: MachineConfig,
                  find_spec: Callable[[str], Any] = importlib.util.find_spec) -> None:
    """Refuse to start cncd when the config asks for OPC UA and it cannot be served."""
    cfg = config.service.opcua
    if cfg is None:
        return
    if find_spec("asyncua") is None:
        raise OpcuaUnavailable(f"{config.path}: service.opcua is set but the OPC UA library is "
                               "not installed: pip install 'phcnc[opcua]' (or remove the "
                               "section)")
    for key in ("certificate", "private_key"):
        path = getattr(cfg, key)
        if path is not None and not os.access(path, os.R_OK):
            raise OpcuaUnavailable(f"{config.path}: service.opcua.{key}: cannot read {path}")
    if cfg.methods and cfg.users_file is not None:
        from controller.operator.opcua.users import read_users

        read_users(cfg.users_file)


class OpcuaChild:
    def __init__(self, config: MachineConfig, socket_path: str, log: EventLog) -> None:
        self.config, self.socket_path, self.log = config, socket_path, log
        self.proc: subprocess.Popen[bytes] | None = None
        self._stopping = threading.Event()
        self._lock = threading.Lock()
        self.starts = 0

    def start(self) -> None:
        if self.config.service.opcua is None:
            return
        self._spawn()
        threading.Thread(target=self._watch, name="opcua-child", daemon=True).start()

    def _spawn(self) -> None:
        """Start the server; a failure to start it is logged, never cncd's end."""
        with self._lock:
            if self._stopping.is_set():
                return
            try:
                self.proc = subprocess.Popen(
                    [sys.executable, "-m", "controller.operator.opcua.main", "--config",
                     self.config.path, "--socket", self.socket_path],
                    stdin=subprocess.DEVNULL, close_fds=True, start_new_session=True)
            except OSError as exc:
                self.proc = None
                self.log.log(ERR, f"OPC UA server cannot start: {exc}")
                return
            self.starts += 1
        assert self.config.service.opcua is not None
        self.log.log(NOTICE, f"OPC UA server started (pid {self.proc.pid}) on "
                             f"{self.config.service.opcua.endpoint}")

    def _watch(self) -> None:
        failures = 0
        while not self._stopping.is_set():
            proc = self.proc
            what = "did not start"
            if proc is not None:
                code = proc.wait()
                what = f"(pid {proc.pid}) exited with {code}"
            if self._stopping.is_set():
                return
            pause_s = RESTART_AFTER_S[min(failures, len(RESTART_AFTER_S) - 1)]
            failures += 1
            self.log.log(ERR, f"OPC UA server {what}; starting it again in {pause_s:g} s")
            if self._stopping.wait(pause_s):
                return
            self._spawn()

    def stop(self) -> None:
        """SIGTERM to its pid, SIGKILL if it has not gone within STOP_WAIT_S."""
        with self._lock:
            self._stopping.set()
            proc = self.proc
        if proc is None or proc.poll() is not None:
            return
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            self.log.log(ERR, f"OPC UA server (pid {proc.pid}) ignored SIGTERM: killed")
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
