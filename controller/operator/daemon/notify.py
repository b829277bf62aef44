"""systemd's notify protocol in a few lines (READY, WATCHDOG, STATUS, STOPPING), no libsystemd."""

from __future__ import annotations

import os
import socket
import threading
from collections.abc import Callable


def sd_notify(message: str) -> bool:
    """One datagram to $NOTIFY_SOCKET; False when not under systemd or when it cannot be sent.
    Never blocks: a lost notification must not stall the controller."""
    addr = os.environ.get("NOTIFY_SOCKET")
    if not addr:
        return False
    if addr[0] == "@":
        addr = "\0" + addr[1:]  # abstract namespace
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
            s.setblocking(False)
            s.connect(addr)
            s.sendall(message.encode())
    except OSError:
        return False
    return True


def watchdog_interval_s() -> float | None:
    """Half of WatchdogSec (what sd_watchdog_enabled advises), or None without a watchdog."""
    usec = os.environ.get("WATCHDOG_USEC", "")
    pid = os.environ.get("WATCHDOG_PID", "")
    if not usec.isdigit() or (pid and pid != str(os.getpid())):
        return None
    return int(usec) / 2e6


def run_watchdog(healthy: Callable[[], str | None], stop: threading.Event,
                 on_unhealthy: Callable[[str], None]) -> None:
    """Ping WATCHDOG=1 every half period while healthy() returns None; when it names a problem,
    stop pinging (systemd then restarts the service) and report the problem once."""
    interval_s = watchdog_interval_s()
    if interval_s is None:
        return
    reported = False
    while not stop.wait(interval_s):
        problem = healthy()
        if problem is None:
            sd_notify("WATCHDOG=1")
            reported = False
        elif not reported:
            on_unhealthy(problem)
            reported = True
