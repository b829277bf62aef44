"""The daemon's log: journald-style lines on stderr (`<N>` priority prefixes) and the last
events in memory for `cncctl log`."""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, TextIO

# syslog priorities, as journald reads them from a `<N>` prefix on stderr
ERR, WARNING, NOTICE, INFO, DEBUG = 3, 4, 5, 6, 7
_NAMES = {ERR: "err", WARNING: "warning", NOTICE: "notice", INFO: "info", DEBUG: "debug"}


class EventLog:
    """Thread-safe: every event is written to the stream and kept (the last `keep`); each
    listener (a `cncctl log -f` connection) is called with the event dict."""

    def __init__(self, keep: int = 1000, stream: TextIO | None = None) -> None:
        self._events: deque[dict[str, Any]] = deque(maxlen=keep)
        self._lock = threading.Lock()
        self._stream = stream if stream is not None else sys.stderr
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        self.warned: set[str] = set()

    def log(self, priority: int, message: str) -> None:
        event = {"time": round(time.time(), 3), "priority": _NAMES.get(priority, "info"),
                 "message": message}
        with self._lock:
            self._events.append(event)
            listeners = list(self.listeners)
        try:
            self._stream.write(f"<{priority}>{message}\n")
            self._stream.flush()
        except (OSError, ValueError):
            pass  # a closed stderr must not stop the controller
        for listener in listeners:
            listener(event)

    def warn_once(self, key: str, message: str) -> None:
        if key not in self.warned:
            self.warned.add(key)
            self.log(WARNING, message)

    def last(self, n: int) -> list[dict[str, Any]]:
        with self._lock:
            return list(self._events)[-n:] if n else []
