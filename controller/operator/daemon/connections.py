"""A control-socket connection: what it is receiving (a request line, a program spooled to a
file) and owes, and which one makes room for a newcomer at the connection cap."""

from __future__ import annotations

import socket
import tempfile
import time
from dataclasses import dataclass, field

from controller.operator.daemon.protocol import LineReader, Request

NEW_GRACE_S = 1.0  # a connection this young may have its request unread yet: evicted last
CONNECTS_PER_S = 200  # what one process may open, on average (cncctl opens one or two)
CONNECT_BURST = 400  # and at once


class ConnectRate:
    """A token bucket per client process (SO_PEERCRED's pid): a process that connects faster
    than CONNECTS_PER_S is refused at once, unread, which costs the daemon little. Serving a
    flood in full (6,800 connections a second from one process with four threads) kept the
    listen queue full and made a status request wait 1.8 s behind it."""

    def __init__(self, per_s: float = CONNECTS_PER_S, burst: float = CONNECT_BURST) -> None:
        self.per_s, self.burst = per_s, burst
        self._tokens: dict[int, tuple[float, float]] = {}  # pid -> (tokens, when)

    def allow(self, pid: int, now: float) -> bool:
        tokens, then = self._tokens.get(pid, (self.burst, now))
        tokens = min(self.burst, tokens + (now - then) * self.per_s)
        if len(self._tokens) > 4096:
            self._forget_full(now)
        if tokens < 1.0:
            self._tokens[pid] = (tokens, now)
            return False
        self._tokens[pid] = (tokens - 1.0, now)
        return True

    def _forget_full(self, now: float) -> None:
        """Processes whose bucket has refilled are as if never seen: the table stays small."""
        refill_s = self.burst / self.per_s
        self._tokens = {pid: v for pid, v in self._tokens.items() if now - v[1] < refill_s}


class Upload:
    """A program arriving after its run request, spooled to an unlinked temporary file: not
    in the daemon's memory, which mlockall pins (16 clients trickling 64 MiB programs held
    1.36 GB of locked RAM)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.received = 0
        self.file = tempfile.TemporaryFile(prefix="cncd-upload-")  # noqa: SIM115

    def add(self, data: bytes) -> None:
        self.file.write(data)
        self.received += len(data)

    def text(self) -> bytes:
        self.file.seek(0)
        data = self.file.read()
        self.close()
        return data

    def close(self) -> None:
        self.file.close()


@dataclass(eq=False)
class Conn:
    sock: socket.socket
    uid: int
    reader: LineReader = field(default_factory=LineReader)
    out: bytearray = field(default_factory=bytearray)
    topics: set[str] = field(default_factory=set)
    last_s: float = field(default_factory=time.monotonic)
    admitted_s: float = field(default_factory=time.monotonic)
    request_s: float | None = None  # when the request now being received began
    run: tuple[Request, Upload] | None = None  # a run request waiting for its program
    discard: int = 0  # program bytes still to skip after a refused run
    closing: bool = False  # close once `out` is sent
    following: bool = False  # receives the events of the job it started

    @property
    def receiving(self) -> bool:
        return self.run is not None or bool(self.discard) or bool(self.reader.pending)

    @property
    def idle(self) -> bool:
        """Nothing owed either way: may be closed to make room for another client."""
        return (not self.topics and not self.following and self.run is None
                and not self.reader.pending)


def eviction_rank(conn: Conn, now: float) -> tuple[int, float]:
    """Lower goes first (Server._evict_idle): an idle connection past its grace, then the
    longest trickle, then the quietest subscriber, then a young idle one."""
    young = now - conn.admitted_s < NEW_GRACE_S
    if conn.idle and not conn.out and not young:
        return 0, conn.last_s
    if conn.receiving:
        return 1, conn.request_s or now
    if conn.topics:
        return 2, conn.last_s
    return 3, conn.admitted_s
