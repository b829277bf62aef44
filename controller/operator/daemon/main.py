"""`cncd`: the controller as a service. Owns the drive for its whole life, serves the control
socket, runs one job at a time, speaks systemd's notify protocol, stops under control on
SIGTERM. Runs in the foreground, with or without systemd."""

from __future__ import annotations

import argparse
import ctypes
import errno
import os
import signal
import sys
import threading
import time
from pathlib import Path

from controller.config import CONFIG_HELP, MachineConfig, load_config
from controller.errors import CncError
from controller.motion.realtime import probe_scheduling, realtime_threads, service_nice
from controller.operator.client import default_socket_path, estop_socket_path
from controller.operator.daemon.access import AccessPolicy, bind_socket, socket_gid
from controller.operator.daemon.estop_socket import EstopSocket
from controller.operator.daemon.job import PROGRESS_EVERY_S
from controller.operator.daemon.log import ERR, INFO, NOTICE, WARNING, EventLog
from controller.operator.daemon.machine import Machine
from controller.operator.daemon.notify import run_watchdog, sd_notify
from controller.operator.daemon.opcua_child import OpcuaChild, require_opcua
from controller.operator.daemon.protocol import ProtocolError
from controller.operator.daemon.server import Server
from controller.operator.daemon.web_process import WebProcess, WebProcessError, check_listen
from controller.operator.drive_args import add_drive_option_argument, config_with_drive_options
from controller.runtime.processes import RuntimeOptions

STOP_TIMEOUT_S = 20.0  # SIGTERM: the running job's controlled stop must end within this
SERVER_STALL_S = 1.0  # the socket loop silent this long: unhealthy (no WATCHDOG=1)


def default_state_dir() -> str:
    return os.environ.get("STATE_DIRECTORY", "/var/lib/cncd").split(":")[0]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cncd", description="phcnc controller daemon")
    ap.add_argument("--config", help=CONFIG_HELP)
    # The defaults come from the environment: a % in them must not break --help (argparse
    # %-formats help strings).
    socket_default = default_socket_path().replace("%", "%%")
    state_default = default_state_dir().replace("%", "%%")
    ap.add_argument("--socket", help=f"control socket (default: {socket_default})")
    ap.add_argument("--state-dir", help=f"job journal (default: {state_default})")
    ap.add_argument("--http", metavar="HOST:PORT",
                    help="serve the web panel and its API there (default: service.http; "
                         "127.0.0.1 when HOST is left out)")
    ap.add_argument("--http-token-file", help="the API token (default: "
                                              "service.http_token_file); needed beyond the "
                                              "loopback")
    add_drive_option_argument(ap)
    return ap


def _arguments(argv: list[str] | None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def _lock_memory(log: EventLog) -> None:
    """mlockall where permitted (LimitMEMLOCK), one warning otherwise: page faults on the
    motion thread's path are the latency a service can avoid.

    MCL_ONFAULT locks each page once it is used rather than every page mapped: OpenBLAS's
    32 MiB buffer, never used here, and 8 MiB for each thread's stack were made resident and
    locked (182 MB idle); a page in use is never paged out all the same."""
    libc = ctypes.CDLL(None, use_errno=True)
    mcl_current, mcl_future, mcl_onfault = 1, 2, 4
    if libc.mlockall(mcl_current | mcl_future | mcl_onfault) == 0:
        log.log(INFO, "memory locked (pages as they are used)")
        return
    if ctypes.get_errno() == errno.EINVAL and libc.mlockall(mcl_current | mcl_future) == 0:
        log.log(INFO, "memory locked (a kernel before 4.4: every page mapped)")
        return
    err = ctypes.get_errno()
    log.warn_once("mlock", f"memory not locked ({os.strerror(err)}): raise LimitMEMLOCK "
                           "for fewer latency spikes")


def _job_options() -> RuntimeOptions:
    """A job's progress every PROGRESS_EVERY_S (the web panel's 25 Hz status push)."""
    return RuntimeOptions(settings={"progress_every_s": PROGRESS_EVERY_S})


class Daemon:
    def __init__(self, config: MachineConfig, socket_path: str, state_dir: Path,
                 log: EventLog) -> None:
        from drivers.registry import make_drive

        self.config, self.socket_path, self.log = config, socket_path, log
        self.stop = threading.Event()
        self.drive = make_drive(config, realtime=True)
        sched = probe_scheduling()
        log.log(INFO if sched.privileged else WARNING, f"scheduling: {sched.summary()}")
        with realtime_threads():  # the drive's threads (card clock, link) as the motion thread
            self.drive.open()
        self.server: Server | None = None
        self.machine = Machine(config, self.drive, state_dir, log, self._publish,
                               runtime_options=_job_options)
        self.machine.scheduling = sched.as_dict()
        self.web: WebProcess | None = None
        self.failed = False  # the web panel asked for did not start

    def _start_web(self) -> None:
        """Off the socket loop, which the panel needs to answer it; READY=1 once it serves."""
        assert self.web is not None
        try:
            self.web.start()
        except WebProcessError as exc:
            self.log.log(ERR, f"cncd: cannot start: {exc}")
            self.failed = True
            self.stop.set()
            return
        self._ready()
        # This thread lives as long as the panel: the kernel's parent-death signal, which
        # stops the panel if cncd dies, follows the thread that started it.
        self.web.wait()

    def _ready(self) -> None:
        sd_notify(f"READY=1\nSTATUS={self.machine.state.value}\nMAINPID={os.getpid()}")
        self.log.log(NOTICE, f"ready on {self.socket_path} ({self.config.name}, drive "
                             f"{self.config.drive.backend}); state {self.machine.state.value}")

    def _publish(self, topic: str, event: dict) -> None:
        if self.server is not None:
            self.server.publish(topic, event)
        if topic == "state":
            sd_notify(f"STATUS={event['state']}" + (f": {event['fault']}"
                                                    if event.get("fault") else ""))

    def serve(self) -> None:
        service_nice()  # this thread serves the control socket (the e-stop thread inherits it)
        gid = socket_gid(self.config.service)
        listener = bind_socket(self.socket_path, gid)
        policy = AccessPolicy(self.config.service, gid)
        self.server = Server(listener, self.machine, self.log, policy,
                             self.config.service.max_connections)
        self.log.listeners.append(lambda event: self.server.publish("log", {  # type: ignore
            "event": "log", **event}))
        estop = EstopSocket(estop_socket_path(self.socket_path), gid, policy, self.log,
                            self._estop)
        estop.start()
        opcua = OpcuaChild(self.config, self.socket_path, self.log)
        opcua.start()  # a client of the socket: it connects once the loop below serves
        threading.Thread(target=run_watchdog, args=(self._healthy, self.stop, self._unhealthy),
                         name="watchdog", daemon=True).start()
        if self.web is not None:
            threading.Thread(target=self._start_web, name="web-start", daemon=True).start()
        else:
            self._ready()
        try:
            self.server.serve(self._keep_going)
        finally:
            if self.web is not None:
                self.web.stop()
            opcua.stop()
            estop.close()
            listener.close()
            try:
                os.unlink(self.socket_path)
            except OSError:
                pass

    def _estop(self, reason: str) -> str:
        self.machine.estop(reason)
        return self.machine.state.value

    def _keep_going(self) -> bool:
        if not self.stop.is_set():
            return True
        # Stopping: serve on until the running job has come to rest, so its client sees it.
        if self._stop_deadline_s is None:
            self._stop_deadline_s = time.monotonic() + STOP_TIMEOUT_S
        return not self.machine.wait_idle(0.0) and time.monotonic() < self._stop_deadline_s

    _stop_deadline_s: float | None = None

    def terminate(self, signum: int) -> None:
        name = signal.Signals(signum).name
        sd_notify("STOPPING=1")
        self.log.log(NOTICE, f"{name}: stopping (a running job stops along the path)")
        self.machine.terminate(f"daemon stopping ({name})")
        self.stop.set()

    def _healthy(self) -> str | None:
        quiet_s = time.monotonic() - (self.server.beat_s if self.server else 0.0)
        if quiet_s > SERVER_STALL_S:
            return f"control socket loop silent for {quiet_s:.1f} s"
        return self.machine.healthy()

    def _unhealthy(self, problem: str) -> None:
        self.log.log(ERR, f"watchdog withheld: {problem}")

    def close(self) -> None:
        self.machine.wait_idle(STOP_TIMEOUT_S)
        try:
            self.drive.close()
        except CncError as exc:
            self.log.log(ERR, f"closing the drive: {exc}")


def main(argv: list[str] | None = None) -> int:
    args = _arguments(argv)
    try:
        config = config_with_drive_options(load_config(args.config), args.drive_option)
        require_opcua(config)
    except CncError as exc:
        print(f"<3>cncd: {exc}", file=sys.stderr)
        return 2
    log = EventLog(config.service.log_events)
    state_dir = Path(args.state_dir or default_state_dir())
    socket_path = args.socket or default_socket_path()
    try:
        state_dir.mkdir(mode=0o750, parents=True, exist_ok=True)
        _lock_memory(log)
        http = args.http or config.service.http
        token_file = args.http_token_file or config.service.http_token_file
        if http:  # before the drive is opened: a panel that may not serve stops everything
            check_listen(http, token_file)
        daemon = Daemon(config, socket_path, state_dir, log)
        if http:
            daemon.web = WebProcess(http, token_file, socket_path, state_dir, args.config, log)
    except (CncError, OSError, ProtocolError) as exc:
        log.log(ERR, f"cncd: cannot start: {exc}")
        return 1
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, _frame: daemon.terminate(signum))
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # no config reload: restart to apply one
    try:
        daemon.serve()
    except Exception as exc:  # noqa: BLE001  (the socket failed, or a bug: stop the job too)
        if isinstance(exc, OSError):
            log.log(ERR, f"cncd: control socket: {exc}")
            reason = "control socket failed"
        else:
            log.log(ERR, f"cncd: internal error: {type(exc).__name__}: {str(exc)[:200]}")
            reason = "internal error"
        daemon.machine.terminate(f"daemon stopping ({reason})")
        if daemon.web is not None:
            daemon.web.stop()
        daemon.close()
        return 1
    daemon.close()
    log.log(NOTICE, "stopped")
    return 1 if daemon.failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
