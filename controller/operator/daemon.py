"""`python -m controller.operator.daemon`: a minimal cncd (sd_notify READY/WATCHDOG, run requests).

Protocol on a Unix stream socket, one JSON object per line:
  -> {"cmd": "run", "program": PATH, "virtual_time": false}
  <- {"event": "start"...}, {"event": "progress"...}, ..., final {"event": "done"|"fault"|...}
     or {"event": "rejected", "message": "PROGRAM:LINE:COL: error: ..."}
  -> {"cmd": "abort"}   (any connection: stop the running job along the path)
  -> {"cmd": "status"}  <- {"event": "status", "busy": bool}
One job at a time; a restart never resumes motion (jobs are not persisted).
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import signal
import socket
import threading
import time
from pathlib import Path
from typing import Any

from controller.config import MachineConfig, load_config
from controller.errors import NcError
from controller.operator.run_cmd import check_program
from controller.operator.run_view import JsonView
from controller.runtime.processes import Runtime, RuntimeOptions


def sd_notify(message: str) -> bool:
    """Datagram to $NOTIFY_SOCKET (no libsystemd needed); False when not under systemd."""
    addr = os.environ.get("NOTIFY_SOCKET")
    if not addr:
        return False
    if addr[0] == "@":
        addr = "\0" + addr[1:]  # abstract namespace
    # Never block nor fail the controller on a slow or absent manager (the datagram queue
    # can be as short as 10): a lost notification is reported as False.
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
            s.setblocking(False)
            s.connect(addr)
            s.sendall(message.encode())
    except OSError:
        return False
    return True


class Daemon:
    def __init__(self, config: MachineConfig, socket_path: str) -> None:
        self.config, self.socket_path = config, socket_path
        self.jobs: queue.Queue[tuple[dict[str, Any], socket.socket]] = queue.Queue()
        self.runtime: Runtime | None = None
        self.beat_s = time.monotonic()  # main loop heartbeat, checked before each WATCHDOG=1
        self.stopping = threading.Event()

    def serve(self) -> None:
        Path(self.socket_path).unlink(missing_ok=True)
        server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        server.bind(self.socket_path)
        server.listen(4)
        threading.Thread(target=self._accept, args=(server,), daemon=True).start()
        sd_notify(f"READY=1\nSTATUS=idle\nMAINPID={os.getpid()}")
        threading.Thread(target=self._watchdog, daemon=True).start()
        while not self.stopping.is_set():
            self.beat_s = time.monotonic()
            try:
                request, conn = self.jobs.get(timeout=0.2)
            except queue.Empty:
                continue
            self._run_job(request, conn)
        sd_notify("STOPPING=1")
        server.close()
        Path(self.socket_path).unlink(missing_ok=True)

    def _watchdog(self) -> None:
        usec = int(os.environ.get("WATCHDOG_USEC", "0"))
        if not usec:
            return
        interval_s = usec / 2e6
        while not self.stopping.is_set():
            # Ping only while the main loop is alive: a hung daemon gets restarted by systemd.
            if time.monotonic() - self.beat_s < interval_s * 2:
                sd_notify("WATCHDOG=1")
            time.sleep(interval_s)

    def _accept(self, server: socket.socket) -> None:
        while not self.stopping.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                return
            threading.Thread(target=self._client, args=(conn,), daemon=True).start()

    def _client(self, conn: socket.socket) -> None:
        line = conn.makefile("r").readline()
        try:
            request = json.loads(line)
        except json.JSONDecodeError:
            request = {}
        cmd = request.get("cmd")
        if cmd == "run":
            self.jobs.put((request, conn))  # the main thread owns the connection now
            return
        if cmd == "abort" and self.runtime is not None:
            self.runtime.request_abort("aborted by operator (control socket)")
        reply = {"event": "status", "busy": self.runtime is not None} if cmd in (
            "status", "abort") else {"event": "error", "message": f"unknown request {line!r}"}
        conn.sendall((json.dumps(reply) + "\n").encode())
        conn.close()

    def _run_job(self, request: dict[str, Any], conn: socket.socket) -> None:
        out = conn.makefile("w")
        view = JsonView(out)
        program = str(request.get("program", ""))
        try:
            check_program(program, self.config)
        except NcError as exc:
            view.event("rejected", message=exc.format())
            out.close()
            conn.close()
            return

        def progress(p: Any) -> None:
            self.beat_s = time.monotonic()
            try:
                view.progress(p)
            except OSError:
                pass  # the client went away: the job goes on (abort via the socket)
        self.runtime = Runtime(program, self.config, RuntimeOptions(
            virtual_time=bool(request.get("virtual_time", False)), on_progress=progress))
        sd_notify(f"STATUS=running {program}")
        try:
            view.event("start", program=program, config=self.config.name)
            view.final(self.runtime.run())
        except OSError:
            pass
        finally:
            self.runtime = None
            sd_notify("STATUS=idle")
            out.close()
            conn.close()

    def terminate(self) -> None:
        """SIGTERM: stop the running job along the path, then leave the serve loop."""
        if self.runtime is not None:
            self.runtime.request_abort("daemon stopping (SIGTERM)")
        self.stopping.set()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="cncd", description=__doc__.splitlines()[0])
    ap.add_argument("--config")
    ap.add_argument("--socket", default=os.path.join(
        os.environ.get("RUNTIME_DIRECTORY", "/run/cncd"), "control.sock"))
    args = ap.parse_args(argv)
    daemon = Daemon(load_config(args.config), args.socket)
    signal.signal(signal.SIGTERM, lambda *_: daemon.terminate())
    signal.signal(signal.SIGINT, lambda *_: daemon.terminate())
    daemon.serve()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
