"""The control socket: one selector thread serves every connection, checks who is calling
(SO_PEERCRED), caps sizes, connections and idle time, and hands commands to the Machine."""

from __future__ import annotations

import errno
import queue
import resource
import selectors
import socket
import struct
import time
from typing import Any

from controller.operator.daemon.access import AccessPolicy
from controller.operator.daemon.connections import Conn, ConnectRate, Upload, eviction_rank
from controller.operator.daemon.log import ERR, INFO, WARNING, EventLog
from controller.operator.daemon.machine import Machine
from controller.operator.daemon.protocol import (
    MAX_PROGRAM_BYTES,
    ProtocolError,
    Request,
    encode,
    parse_request,
    reply_error,
    reply_ok,
)

READ_TIMEOUT_S = 10.0  # a request begun (partial line or program) must be complete by then
IDLE_TIMEOUT_S = 300.0  # a connection with nothing pending and no subscription is closed
MAX_UPLOADS_BYTES = 2 * MAX_PROGRAM_BYTES  # programs being received at once, all clients
MAX_OUTPUT_BYTES = 4 << 20  # a subscriber this far behind is dropped (never blocks the daemon)
_RECV_BYTES = 1 << 16
ACCEPT_BATCH = 4096  # connections taken from the listen queue per turn of the loop


class Server:
    def __init__(self, listener: socket.socket, machine: Machine, log: EventLog,
                 policy: AccessPolicy, max_connections: int) -> None:
        self.listener, self.machine, self.log, self.policy = listener, machine, log, policy
        self.max_connections = _connection_cap(max_connections)
        self.sel = selectors.DefaultSelector()
        self.sel.register(listener, selectors.EVENT_READ, None)
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self.sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        self.inbox: queue.SimpleQueue[tuple[Conn | None, str | None, dict[str, Any]]] = (
            queue.SimpleQueue())
        self.conns: set[Conn] = set()
        self.beat_s = time.monotonic()
        self._accept_paused_until = 0.0
        self.rate = ConnectRate()

    # -- from other threads -------------------------------------------------------------------
    def publish(self, topic: str, event: dict[str, Any]) -> None:
        self._post(None, topic, event)

    def emitter(self, conn: Conn) -> Any:
        return lambda event: self._post(conn, None, event)

    def _post(self, conn: Conn | None, topic: str | None, event: dict[str, Any]) -> None:
        self.inbox.put((conn, topic, event))
        try:
            self._wake_w.send(b"\0")
        except OSError:
            pass  # the wake-up pipe is full: the loop is already awake

    # -- the loop -----------------------------------------------------------------------------
    def serve(self, keep_going: Any) -> None:
        while keep_going():
            self.beat_s = time.monotonic()
            for key, mask in self.sel.select(timeout=0.1):
                if key.data is None:
                    self._accept()
                elif key.data == "wake":
                    self._drain_wake()
                else:
                    self._service(key.data, mask)
            self._deliver()
            self._expire()
        self._deliver()
        self._drain_output(deadline_s=time.monotonic() + 1.0)
        for conn in list(self.conns):
            self._close(conn)

    def _drain_output(self, deadline_s: float) -> None:
        """On the way out: give clients up to a second to take what is owed to them."""
        while time.monotonic() < deadline_s and any(c.out for c in self.conns):
            for conn in [c for c in self.conns if c.out]:
                self._flush(conn)
            time.sleep(0.01)

    def _accept(self) -> None:
        if time.monotonic() < self._accept_paused_until:
            return
        # The whole queue is taken each time (accepting costs little next to serving): a
        # queue left full refuses every newcomer, the operator's `reset` among the flood.
        for _ in range(ACCEPT_BATCH):
            try:
                sock, _ = self.listener.accept()
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    # Out of descriptors: free idle ones and retry shortly, never stop accepting.
                    self.log.warn_once("emfile", f"control socket: {exc.strerror}; closing "
                                                 "idle connections")
                    self._evict_idle(all_of_them=True)
                    self._accept_paused_until = time.monotonic() + 0.05
                return
            self._admit(sock)

    def _admit(self, sock: socket.socket) -> None:
        sock.setblocking(False)
        pid, uid, gid = struct.unpack("3i", sock.getsockopt(
            socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i")))
        if not self.rate.allow(pid, time.monotonic()):
            self.log.warn_once("connect-rate", f"control socket: pid {pid} (uid {uid}) connects "
                                              f"more than {self.rate.per_s:.0f} times a second: "
                                              "its connections are refused unread")
            _send_now(sock, reply_error(None, "too-many-connections", "this process connects "
                                        "too often: try again in a moment"))
            sock.close()
            return
        if not self.policy.allows(pid, uid, gid):
            self.log.log(WARNING, f"control socket: refused uid {uid} gid {gid} (pid {pid})")
            _send_now(sock, reply_error(None, "unauthorised", "not allowed: ask to be added to "
                                                              "the service group"))
            sock.close()
            return
        if len(self.conns) >= self.max_connections and not self._evict_idle():
            _send_now(sock, reply_error(None, "too-many-connections",
                                        f"too many connections ({self.max_connections})"))
            sock.close()
            return
        conn = Conn(sock, uid)
        self.conns.add(conn)
        self.sel.register(sock, selectors.EVENT_READ, conn)

    def _evict_idle(self, all_of_them: bool = False) -> bool:
        """Make room for a newcomer (or every idle one, out of descriptors): first an idle
        connection past its grace, then one whose request has been arriving longest (a
        trickle), then the subscriber quiet longest, then a young idle one; never one following
        the job it started. (Subscribers were never evicted: 64 silent ones locked `estop` out.)"""
        now = time.monotonic()
        idle = sorted((c for c in self.conns if c.idle and not c.out), key=lambda c: c.last_s)
        if all_of_them:
            for conn in idle:
                self._close(conn)
            return bool(idle)
        # A young connection whose request waits unread in the kernel is served now, not
        # evicted as idle: under a flood of reconnections a `reset` was closed unanswered.
        for conn in [c for c in self.conns if c.idle and not c.out and _unread(c.sock)]:
            self._service(conn, selectors.EVENT_READ)
        if len(self.conns) < self.max_connections:  # serving closed some (clients hung up)
            return True
        ranked = sorted((c for c in self.conns if not c.following),
                        key=lambda c: eviction_rank(c, now))
        if not ranked:
            return False
        self._close(ranked[0])
        return True

    def _service(self, conn: Conn, mask: int) -> None:
        if mask & selectors.EVENT_WRITE:
            self._flush(conn)
        if mask & selectors.EVENT_READ and conn in self.conns:
            try:
                data = conn.sock.recv(_RECV_BYTES)
            except BlockingIOError:
                return
            except OSError:
                data = b""
            if not data:
                self._close(conn)
                return
            conn.last_s = time.monotonic()
            if conn.request_s is None:
                conn.request_s = conn.last_s  # a request's deadline runs from its first byte
            try:
                conn.reader.feed(data)
                self._consume(conn)
                if not conn.receiving:
                    conn.request_s = None
            except ProtocolError as exc:  # framing lost: answer, then hang up
                self._send(conn, reply_error(None, exc.code, exc.message))
                conn.closing = True
                self._flush(conn)

    def _consume(self, conn: Conn) -> None:
        while not conn.closing:
            if conn.discard:
                conn.discard -= len(conn.reader.take(conn.discard))
                if conn.discard:
                    return
            if conn.run is not None:
                request, upload = conn.run
                upload.add(conn.reader.take(upload.size - upload.received))
                if upload.received < upload.size:
                    return
                conn.run = None
                self._start_run(conn, request, upload.text())
                continue
            line = conn.reader.next_line()
            if line is None:
                return
            self._request(conn, line)

    def _request(self, conn: Conn, line: bytes) -> None:
        try:
            request = parse_request(line)
        except ProtocolError as exc:
            self._send(conn, reply_error(None, exc.code, exc.message))
            return
        except Exception as exc:  # noqa: BLE001  (a request never takes the daemon down)
            self._internal_error(conn, None, "reading a request", exc)
            return
        try:
            self._dispatch(conn, request)
        except ProtocolError as exc:
            self._send(conn, reply_error(request.id, exc.code, exc.message))
        except Exception as exc:  # noqa: BLE001  (the job and the other clients go on)
            self._internal_error(conn, request.id, request.cmd, exc)

    def _internal_error(self, conn: Conn, request_id: Any, what: str, exc: Exception) -> None:
        """A bug met by one request: logged (type and a bounded message, for the report),
        answered, and nothing else changed: the job runs on and the daemon serves on."""
        self.log.log(ERR, f"control socket: internal error in {what}: {type(exc).__name__}: "
                          f"{str(exc)[:200]}")
        self._send(conn, reply_error(request_id, "internal", "internal error: see cncctl log"))

    def _dispatch(self, conn: Conn, request: Request) -> None:
        who = f"control socket, uid {conn.uid}"
        cmd, rid = request.cmd, request.id
        if cmd == "status":
            self._send(conn, reply_ok(rid, **self.machine.status()))
        elif cmd == "run":
            try:
                self.machine.require_idle()
            except ProtocolError:
                # Refused at once: the program text that follows is skipped unread.
                conn.discard = request.fields["program_bytes"]
                raise
            size = request.fields["program_bytes"]
            uploading = sum(c.run[1].size for c in self.conns if c.run is not None)
            if uploading + size > MAX_UPLOADS_BYTES:
                conn.discard = size
                raise ProtocolError("busy", f"programs being sent take {uploading} bytes; "
                                            f"{MAX_UPLOADS_BYTES} at most at once: try again")
            conn.run = (request, Upload(size))
        elif cmd == "abort":
            state = self.machine.abort(f"aborted by operator ({who})")
            self._send(conn, reply_ok(rid, state=state))
        elif cmd == "estop":
            self.machine.estop(f"e-stop by operator ({who})")
            self._send(conn, reply_ok(rid, state=self.machine.state.value))
        elif cmd == "hold":
            self.machine.hold()
            # The stop along the path takes a moment: HELD once at a standstill.
            held = self.machine.status()["state"] == "HELD"
            self._send(conn, reply_ok(rid, state="HELD" if held else "HOLDING"))
        elif cmd == "resume":
            self.machine.resume()
            if self.machine.feed_override_pct == 0.0:
                self._send(conn, reply_ok(rid, state="HELD", note="the feed override is 0 %: "
                                          "the job moves once it is raised (cncctl feed)"))
            else:
                self._send(conn, reply_ok(rid, state="RUNNING"))
        elif cmd == "home":
            self.machine.home(list(request.fields.get("axes", [])))
            self._send(conn, reply_ok(rid, state=self.machine.state.value))
        elif cmd == "jog":
            self._start_jog(conn, request)
        elif cmd == "identify":  # answered from a thread: the excitations take a moment
            conn.following = request.fields.get("follow", True) and not request.fields.get(
                "plan_only", False)
            self.machine.identify(request.fields, rid, self.emitter(conn))
        elif cmd == "offset":
            f = request.fields
            self._send(conn, reply_ok(rid, offsets=self.machine.offset(
                f["action"], f.get("system"), f.get("values", {}), f.get("here", False))))
        elif cmd == "tool":  # list, set, delete (daemon/tool_store.py)
            self._send(conn, reply_ok(rid, **self.machine.tool(request.fields)))
        elif cmd == "feed":
            self.machine.feed(float(request.fields["percent"]))
            self._send(conn, reply_ok(rid, feed_override_pct=self.machine.feed_override_pct))
        elif cmd == "reset":
            self.machine.reset()
            self._send(conn, reply_ok(rid, state=self.machine.state.value))
        elif cmd == "log":
            self._send(conn, reply_ok(rid, events=self.log.last(request.fields.get("lines", 50))))
            if request.fields.get("follow"):
                conn.topics.add("log")
        elif cmd == "subscribe":
            conn.topics.update(request.fields.get("topics", ["state"]))
            self._send(conn, reply_ok(rid, topics=sorted(conn.topics)))

    def _start_jog(self, conn: Conn, request: Request) -> None:
        f = request.fields
        follow = f.get("follow", False)
        emit = self.emitter(conn) if follow else (lambda event: None)
        direction = f.get("direction")
        job, note = self.machine.jog(f["axis"].lower(), f.get("distance_mm"),
                                     int(direction) if direction is not None else 0,
                                     float(f.get("feed_mm_min", 600.0)), emit,
                                     f.get("timeout_s", 30.0 if direction is not None else None))
        conn.following = bool(follow)
        self._send(conn, reply_ok(request.id, job=job, state=self.machine.state.value,
                                  message=note))

    def _start_run(self, conn: Conn, request: Request, text: bytes) -> None:
        name = request.fields.get("name", "program.nc")
        follow = request.fields.get("follow", True)
        emit = self.emitter(conn) if follow else (lambda event: None)
        try:
            job = self.machine.start_job(name, text, emit,
                                         optional_stop=request.fields.get("optional_stop", False),
                                         from_line=request.fields.get("from_line"))
        except ProtocolError as exc:
            self._send(conn, reply_error(request.id, exc.code, exc.message))
            return
        conn.following = bool(follow)
        self.log.log(INFO, f"job {job}: {name!r} ({len(text)} bytes) from uid {conn.uid}")
        self._send(conn, reply_ok(request.id, job=job, state=self.machine.state.value))

    # -- output -------------------------------------------------------------------------------
    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except BlockingIOError:
            pass

    def _deliver(self) -> None:
        while True:
            try:
                conn, topic, event = self.inbox.get_nowait()
            except queue.Empty:
                return
            data = encode(event)
            targets = ([conn] if conn is not None else
                       [c for c in self.conns if topic in c.topics])
            for target in targets:
                if target in self.conns:
                    self._send(target, data)

    def _send(self, conn: Conn, data: bytes) -> None:
        conn.out += data
        if len(conn.out) > MAX_OUTPUT_BYTES:
            self.log.log(WARNING, f"control socket: dropped a client {len(conn.out)} bytes "
                                  "behind")
            self._close(conn)
            return
        self._flush(conn)

    def _flush(self, conn: Conn) -> None:
        if conn not in self.conns:
            return
        try:
            sent = conn.sock.send(conn.out) if conn.out else 0
            del conn.out[:sent]
        except BlockingIOError:
            pass
        except OSError:
            self._close(conn)
            return
        if conn.closing and not conn.out:
            self._close(conn)
            return
        want = selectors.EVENT_READ | (selectors.EVENT_WRITE if conn.out else 0)
        self.sel.modify(conn.sock, want, conn)

    def _expire(self) -> None:
        now = time.monotonic()
        for conn in list(self.conns):
            quiet_s = now - conn.last_s
            # The whole request must arrive within READ_TIMEOUT_S of its first byte: a byte
            # every 5 s used to restart the clock and hold a slot for ever.
            if conn.receiving and now - (conn.request_s or now) > READ_TIMEOUT_S:
                self._send(conn, reply_error(None, "timeout", f"request not completed within "
                                                              f"{READ_TIMEOUT_S:.0f} s"))
                conn.closing = True
                self._flush(conn)
            elif conn.idle and not conn.out and quiet_s > IDLE_TIMEOUT_S:
                self._close(conn)

    def _close(self, conn: Conn) -> None:
        if conn.run is not None:
            conn.run[1].close()
            conn.run = None
        if conn in self.conns:
            self.conns.discard(conn)
            try:
                self.sel.unregister(conn.sock)
            except (KeyError, ValueError):
                pass
            conn.sock.close()


def _unread(sock: socket.socket) -> bool:
    """Bytes the client sent that the daemon has not read yet."""
    try:
        return bool(sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT))
    except OSError:  # BlockingIOError (nothing there) or a reset: nothing to serve
        return False


def _send_now(sock: socket.socket, data: bytes) -> None:
    try:
        sock.send(data)
    except OSError:
        pass


def _connection_cap(configured: int) -> int:
    """At most the configured count, and always well inside the descriptor limit."""
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return max(4, min(configured, (soft - 64) // 2 if soft > 0 else configured))

