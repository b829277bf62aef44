"""The e-stop socket: connecting to it is an e-stop, served by a thread of its own, no slot needed.

The control socket has a connection cap, request deadlines and one selector loop shared with
every client: 64 silent subscribers once filled it and `cncctl estop` answered
"too-many-connections". Here an authorised connection is the request itself: the thread
accepts it, checks who calls (SO_PEERCRED, as the control socket does), e-stops the machine,
answers one JSON line and hangs up. Nothing is read from the client, so a slow or silent one
holds nothing; a flood of connections is a flood of e-stops, which its sender may ask anyway.
"""

from __future__ import annotations

import json
import socket
import struct
import threading
from collections.abc import Callable
from pathlib import Path

from controller.operator.daemon.access import AccessPolicy, bind_socket
from controller.operator.daemon.log import WARNING, EventLog

ACCEPT_POLL_S = 0.2  # how often the thread looks at its stop flag between connections


class EstopSocket:
    """Bound at start-up beside the control socket; estop(reason) -> the state it led to."""

    def __init__(self, path: str, gid: int, policy: AccessPolicy, log: EventLog,
                 estop: Callable[[str], str]) -> None:
        self.path, self.policy, self.log, self.estop = path, policy, log, estop
        self.listener = bind_socket(path, gid)
        self.listener.settimeout(ACCEPT_POLL_S)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="estop-socket", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.listener.close()
        try:
            Path(self.path).unlink()
        except OSError:
            pass

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                sock, _ = self.listener.accept()
            except TimeoutError:
                continue
            except OSError as exc:  # out of descriptors: the next try may succeed
                self.log.warn_once("estop-accept", f"e-stop socket: {exc}")
                self._stop.wait(0.01)
                continue
            with sock:
                self._one(sock)

    def _one(self, sock: socket.socket) -> None:
        sock.settimeout(0.5)
        pid, uid, gid = struct.unpack("3i", sock.getsockopt(
            socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i")))
        if not self.policy.allows(pid, uid, gid):
            self.log.warn_once(f"estop-uid-{uid}", f"e-stop socket: refused uid {uid} gid {gid} "
                                                   f"(pid {pid})")
            _reply(sock, {"ok": False, "error": "unauthorised",
                          "message": "not allowed: ask to be added to the service group"})
            return
        try:
            state = self.estop(f"e-stop by operator (e-stop socket, uid {uid})")
        except Exception as exc:  # noqa: BLE001  (the thread must outlive any bug)
            self.log.log(WARNING, f"e-stop socket: {type(exc).__name__}: {str(exc)[:200]}")
            _reply(sock, {"ok": False, "error": "internal", "message": "internal error: see "
                                                                       "cncctl log"})
            return
        _reply(sock, {"ok": True, "state": state})


def _reply(sock: socket.socket, message: dict) -> None:
    try:
        sock.sendall(json.dumps(message).encode() + b"\n")
    except OSError:
        pass  # the client went: the e-stop is done all the same
