"""The web panel as a process of cncd's: started once the control socket is bound, with the
token rule checked first (beyond the loopback only with a token, or cncd refuses to start),
its messages taken into the daemon's log, stopped with the daemon. It is a client of the
control socket: the motion thread and the socket loop do not run its code."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import threading
from pathlib import Path

from controller.errors import CncError
from controller.http_listen import ListenError, is_loopback, parse_listen
from controller.operator.daemon.log import ERR, INFO, EventLog

READY_TIMEOUT_S = 30.0  # the panel's imports and its first status (a loaded PC)
STOP_TIMEOUT_S = 5.0
READY_TEXT = "web panel on "


class WebProcessError(CncError):
    """The panel asked for cannot be served; cncd does not start without it."""


def check_listen(listen: str, token_file: str | None) -> None:
    """The address and the token rule, before anything starts."""
    try:
        host, _ = parse_listen(listen)
    except ListenError as exc:
        raise WebProcessError(f"http {listen!r}: {exc}") from None
    if token_file is None and not is_loopback(host):
        raise WebProcessError(f"http {listen!r}: beyond the loopback the API needs a token "
                              "(service.http_token_file or --http-token-file)")
    if importlib.util.find_spec("aiohttp") is None:
        raise WebProcessError("the web panel needs aiohttp: pip install 'phcnc[web]'")
    if token_file is not None:
        from controller.operator.web.guard import TokenError, read_token

        try:
            read_token(token_file)
        except TokenError as exc:
            raise WebProcessError(f"http token: {exc}") from None


class WebProcess:
    def __init__(self, listen: str, token_file: str | None, socket_path: str,
                 state_dir: Path, config_arg: str | None, log: EventLog) -> None:
        self.log = log
        self.command = [sys.executable, "-m", "controller.operator.web.main",
                        "--socket", socket_path, "--listen", listen,
                        "--state-dir", str(state_dir), "--parent-pid", str(os.getpid())]
        if token_file:
            self.command += ["--token-file", token_file]
        if config_arg:
            self.command += ["--config", config_arg]
        self.proc: subprocess.Popen[bytes] | None = None
        self.ready = threading.Event()
        self.stopping = False

    def start(self) -> None:
        """Start it and wait until it serves; WebProcessError if it does not."""
        self.proc = subprocess.Popen(self.command, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                     close_fds=True)
        threading.Thread(target=self._read_messages, name="web-panel", daemon=True).start()
        if not self.ready.wait(READY_TIMEOUT_S) or self.proc.poll() is not None:
            self.stop()
            raise WebProcessError("the web panel did not start (see the log above)")

    def _read_messages(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for raw in self.proc.stderr:
            text = raw.decode("utf-8", "replace").rstrip()
            priority = INFO
            if len(text) > 3 and text[0] == "<" and text[2] == ">" and text[1].isdigit():
                priority, text = int(text[1]), text[3:]
            self.log.log(priority, text[:500])
            if READY_TEXT in text:
                self.ready.set()
        code = self.proc.wait()
        self.ready.set()  # start() stops waiting on a panel that died
        if not self.stopping:
            self.log.log(ERR, f"web panel exited ({code}): the API and the panel are down; "
                              "restart cncd to serve them again")

    def wait(self) -> None:
        if self.proc is not None:
            self.proc.wait()

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None

    def stop(self) -> None:
        self.stopping = True
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.terminate()
        try:
            self.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
