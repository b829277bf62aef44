"""Keys of an embedded `cncctl run`: space holds or resumes, Enter resumes, + and - the override."""

from __future__ import annotations

import os
import sys
import termios
import threading
import tty
from collections.abc import Callable
from typing import Any, Protocol

from controller.motion.types import MotionProgress, MotionState

OVERRIDE_STEP_PCT = 10.0
MAX_OVERRIDE_PCT = 150.0
HELP = "space: hold/resume  Enter: resume  + / -: feed override  Ctrl-C: stop"


class Operable(Protocol):
    def request_hold(self) -> None: ...

    def request_resume(self) -> None: ...

    def set_feed_override(self, percent: float) -> None: ...


class KeyControl:
    """Turns key presses into operator requests; remembers what the machine is doing so that
    space can mean hold or resume. Keys: ' ' hold/resume, '\\n' resume, '+' '-' override."""

    def __init__(self, target: Operable, say: Callable[[str], None]) -> None:
        self.target, self.say = target, say
        self.override_pct = 100.0
        self.holding = False
        self.state: MotionState | None = None

    def key(self, ch: str) -> None:
        if ch == " ":
            self._toggle_hold()
        elif ch in "\r\n":
            self._resume()
        elif ch in "+=-":
            step = OVERRIDE_STEP_PCT if ch in "+=" else -OVERRIDE_STEP_PCT
            self.override_pct = min(max(self.override_pct + step, 0.0), MAX_OVERRIDE_PCT)
            self.target.set_feed_override(self.override_pct)
            self.say(f"feed override {self.override_pct:g} %")

    def _toggle_hold(self) -> None:
        if self.holding or self.state in (MotionState.HELD, MotionState.PAUSED):
            self._resume()
            return
        self.holding = True
        self.target.request_hold()
        self.say("feed hold: press space to resume")

    def _resume(self) -> None:
        self.holding = False
        self.target.request_resume()

    def progress(self, p: MotionProgress) -> None:
        self.state = p.state


def read_keys(fd: int, on_key: Callable[[str], None]) -> Callable[[], None]:
    """Read keys from fd in a thread (cbreak mode on a terminal: a key at a time, Ctrl-C still
    a signal); returns a function restoring the terminal. os.read on the descriptor, not
    sys.stdin: a thread blocked in sys.stdin holds its buffer's lock, which a forked child
    (the producers) inherits locked and then waits on for ever."""
    saved: list[Any] | None = None
    try:
        if os.isatty(fd):
            saved = termios.tcgetattr(fd)
            tty.setcbreak(fd)
    except (OSError, termios.error):
        saved = None

    def reader() -> None:
        try:
            while data := os.read(fd, 64):
                for ch in data.decode("ascii", errors="ignore"):
                    on_key(ch)
        except (OSError, ValueError):
            pass
    threading.Thread(target=reader, name="run-keys", daemon=True).start()

    def restore() -> None:
        if saved is not None:
            try:
                termios.tcsetattr(fd, termios.TCSADRAIN, saved)
            except (OSError, termios.error):
                pass
    return restore


def stdin_fd() -> int | None:
    try:
        return sys.stdin.fileno()
    except (OSError, ValueError, AttributeError):
        return None
