"""The control socket's client side, as `cncctl` uses it: one request, a reply, then events."""

from __future__ import annotations

import argparse
import json
import os
import socket
import time
from collections.abc import Iterator
from typing import Any

from controller.errors import CncError

CONNECT_TIMEOUT_S = 2.0
SOCKET_NAME = "cncd.sock"


def socket_argument(text: str) -> str:
    """--socket PATH: never empty (an unset variable in `--socket $SOCK` would otherwise mean
    the default socket, or for `run` an embedded run that opens the drive itself)."""
    if not text:
        raise argparse.ArgumentTypeError("empty path")
    return text


def default_socket_path() -> str:
    """$CNCD_SOCKET, else the systemd runtime directory's cncd.sock, else /run/cncd/."""
    explicit = os.environ.get("CNCD_SOCKET")
    if explicit:
        return explicit
    return os.path.join(os.environ.get("RUNTIME_DIRECTORY", "/run/cncd").split(":")[0],
                        SOCKET_NAME)


def connect_unix(sock: socket.socket, path: str, timeout_s: float) -> None:
    """connect(), waiting up to timeout_s while the daemon's listen queue is full: a Unix
    socket with a time-out refuses at once with EAGAIN there (a flood of other clients),
    where a blocking one would wait for room."""
    deadline_s = time.monotonic() + timeout_s
    pause_s = 0.0005
    while True:
        try:
            sock.connect(path)
            return
        except BlockingIOError:
            if time.monotonic() + pause_s > deadline_s:
                raise
            time.sleep(pause_s)
            pause_s = min(pause_s * 2, 0.01)


def refused_through_daemon(args: argparse.Namespace, socket_path: str,
                           embedded_only: tuple[tuple[str, str, str], ...],
                           what: str) -> str | None:
    """Why a command cannot go through the daemon as asked (None: it can): the options of
    `embedded_only` ((attribute, flag, why) each) that were given. A daemon owns its drive,
    config and tables; such an option was once dropped without a word."""
    given = [(flag, why) for attr, flag, why in embedded_only if getattr(args, attr, None)]
    if not given:
        return None
    reasons = "; ".join(f"{flag}: {why}" for flag, why in given)
    return (f"a cncd answers on {socket_path} and cannot honour {reasons}. Nothing was sent "
            f"and nothing moved. Leave the option out to {what} through the daemon, or stop "
            f"cncd (or point CNCD_SOCKET where none answers) for an embedded {what}")


class DaemonUnavailable(CncError):
    """No daemon answers on the socket (absent, stopped, or not allowed to connect)."""


class NoDaemon(DaemonUnavailable):
    """Nothing could connect at all: no request reached a daemon, so nothing moved."""


class DaemonError(CncError):
    """The daemon refused a request; `code` is its reason (busy, estop, unauthorised...)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


class DaemonClient:
    """One connection; requests carry increasing ids, replies are matched by id."""

    def __init__(self, path: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        self.sock.settimeout(timeout_s)
        try:
            connect_unix(self.sock, path, timeout_s)
        except OSError as exc:
            self.sock.close()
            raise NoDaemon(f"no daemon on {path}: {exc.strerror or exc}") from None
        self._file = self.sock.makefile("rb")
        self._next_id = 0

    def request(self, cmd: str, payload: bytes = b"", **fields: Any) -> dict[str, Any]:
        """Send one request (with payload after the line, for run) and return its reply; a
        refusal raises DaemonError."""
        self._next_id += 1
        line = json.dumps({"id": self._next_id, "cmd": cmd, **fields}).encode() + b"\n"
        try:
            self.sock.sendall(line + payload)
        except OSError as exc:
            raise DaemonUnavailable(f"daemon connection lost: {exc}") from None
        for message in self.messages():
            if message.get("id") in (self._next_id, None) and "ok" in message:
                if not message["ok"]:
                    raise DaemonError(message.get("error", "error"), message.get("message", ""))
                return message
        raise DaemonUnavailable("the daemon closed the connection")

    def messages(self, timeout_s: float | None = None) -> Iterator[dict[str, Any]]:
        """Every message as it arrives (replies and pushed events) until the daemon hangs up."""
        self.sock.settimeout(timeout_s)
        while True:
            try:
                line = self._file.readline()
            except (TimeoutError, OSError):
                return
            if not line:
                return
            try:
                yield json.loads(line)
            except ValueError:
                continue

    def close(self) -> None:
        self._file.close()
        self.sock.close()

    def __enter__(self) -> DaemonClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def daemon_answers(path: str) -> bool:
    """True when a daemon accepts connections on path (cncctl run then goes through it)."""
    try:
        with DaemonClient(path, timeout_s=0.5) as client:
            client.request("status")
        return True
    except (DaemonUnavailable, DaemonError, OSError):
        return False


def estop_socket_path(control_socket_path: str) -> str:
    """cncd's e-stop socket beside its control socket: /run/cncd/cncd.sock ->
    /run/cncd/cncd-estop.sock (a connection to it is an e-stop; see daemon/estop_socket.py)."""
    head, tail = os.path.split(control_socket_path)
    stem, dot, suffix = tail.rpartition(".")
    name = f"{stem}-estop.{suffix}" if dot and stem else f"{tail}-estop"
    return os.path.join(head, name)


def request_estop(control_socket_path: str, timeout_s: float = 2.0) -> dict[str, Any] | None:
    """E-stop through the e-stop socket: the daemon's reply, or None when it has none (then
    ask on the control socket). Needs no free connection slot and sends nothing."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
    sock.settimeout(timeout_s)
    try:
        try:
            connect_unix(sock, estop_socket_path(control_socket_path), timeout_s)
        except (FileNotFoundError, ConnectionRefusedError):
            return None
        except OSError as exc:
            raise DaemonUnavailable(f"e-stop socket: {exc.strerror or exc}") from None
        try:
            line = sock.makefile("rb").readline()
        except OSError as exc:
            raise DaemonUnavailable(f"e-stop socket: no answer: {exc}") from None
    finally:
        sock.close()
    try:
        reply = json.loads(line) if line else None
    except ValueError:
        reply = None
    if reply is None:
        raise DaemonUnavailable("e-stop socket: the daemon hung up without an answer")
    if not reply.get("ok"):
        raise DaemonError(reply.get("error", "error"), reply.get("message", ""))
    return reply
