"""The control socket's server meets a bug in one request: it answers, logs, and serves on."""

from __future__ import annotations

import json
import socket

from controller.operator.daemon.log import EventLog
from controller.operator.daemon.server import Conn, Server


class _BrokenMachine:
    """A machine whose status() has a bug."""

    def status(self) -> dict:
        raise RuntimeError("a bug in status")


def test_a_bug_in_a_request_is_answered_and_logged_not_raised() -> None:
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    here, there = socket.socketpair()
    log = EventLog(100)
    server = Server(listener, _BrokenMachine(), log, policy=None, max_connections=8)  # type: ignore[arg-type]
    try:
        conn = Conn(here, 0)
        server._request(conn, b'{"id": 3, "cmd": "status"}')
        reply = json.loads(bytes(conn.out).splitlines()[0])
        assert reply == {"id": 3, "ok": False, "error": "internal",
                         "message": "internal error: see cncctl log"}
        events = log.last(5)
        assert any("internal error in status: RuntimeError: a bug in status" in e["message"]
                   for e in events)
    finally:
        for s in (listener, here, there):
            s.close()


class _Machine:
    def status(self) -> dict:
        return {"state": "IDLE"}


def test_a_full_table_of_clients_that_asked_and_hung_up_makes_room_for_a_newcomer() -> None:
    # Under a flood of connect-ask-hang-up, the table filled with connections whose request
    # was still unread. Serving them closes them all; the newcomer was then refused
    # ("too many connections") because no connection was left to evict.
    import selectors

    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server = Server(listener, _Machine(), EventLog(100), policy=None, max_connections=4)  # type: ignore[arg-type]
    pairs = [socket.socketpair() for _ in range(server.max_connections)]
    try:
        for here, there in pairs:
            here.setblocking(False)
            conn = Conn(here, 0)
            server.conns.add(conn)
            server.sel.register(here, selectors.EVENT_READ, conn)
            there.sendall(b'{"id": 1, "cmd": "status"}\n')
            there.close()
        assert server._evict_idle() is True
        assert len(server.conns) < server.max_connections
    finally:
        for here, there in pairs:
            here.close()
            there.close()
        listener.close()
