"""Keys of an embedded `cncctl run`: space holds or resumes, Enter resumes, + and - the override."""

from __future__ import annotations

import os
import signal
import sys
import termios
import threading
import tty
from collections.abc import Callable
from typing import Any, Protocol

from controller.motion.types import MotionProgress, MotionState
from controller.operator.run.exit_codes import STOP_SIGNALS

OVERRIDE_STEP_PCT = 10.0
MAX_OVERRIDE_PCT = 150.0
HELP = "space: hold/resume  Enter: resume  + / -: feed override  Ctrl-C: stop"


class Operable(Protocol):
    def request_hold(self) -> None: ...

    def request_resume(self) -> None: ...

    def set_feed_override(self, percent: float) -> None: ...

    def request_abort(self, message: str) -> None: ...


class KeyControl:
    """Turns key presses into operator requests; remembers what the machine is doing so that
    space can mean hold or resume. Keys: ' ' hold/resume, '\\n' resume, '+' '-' override."""

    def __init__(self, target: Operable, say: Callable[[str], None],
                 abort_at_pause_without_keys: bool = False) -> None:
        self.target, self.say = target, say
        self.override_pct = 100.0
        self.holding = False
        self.state: MotionState | None = None
        # Embedded runs: the keys are the only way on from an M0, so a standard input at its
        # end aborts the job there (it waited for ever); through cncd, `cncctl resume` can.
        self.abort_at_pause_without_keys = abort_at_pause_without_keys
        self.keys_closed = False
        self._resumed = False  # Enter came during this pause (its resume is on its way)
        self._aborted = False

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
        self._resumed = True
        self.target.request_resume()

    def closed(self) -> None:
        """Standard input is at its end: no key will come."""
        self.keys_closed = True
        self._abort_if_stuck(None)

    def progress(self, p: MotionProgress) -> None:
        if p.state is MotionState.PAUSED and self.state is not MotionState.PAUSED:
            self._resumed = False  # a new pause: a resume must come after it
        self.state = p.state
        self._abort_if_stuck(p.line)

    def _abort_if_stuck(self, line: int | None) -> None:
        if not (self.abort_at_pause_without_keys and self.keys_closed and not self._aborted
                and self.state is MotionState.PAUSED and not self._resumed):
            return
        self._aborted = True
        where = f" at line {line}" if line is not None else ""
        message = (f"standard input closed while paused{where} (M0): nothing can resume "
                   "the job; aborted")
        self.say(message)
        self.target.request_abort(message)


def read_keys(fd: int, on_key: Callable[[str], None],
              on_end: Callable[[], None] | None = None) -> Callable[[], None]:
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
        if on_end is not None:
            on_end()  # at the end of input (or unreadable): no key will come
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


def _cancel(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def enter_to_go(prompt: str, aborted: Callable[[], bool] = lambda: False) -> bool:
    """Print prompt and wait for Enter: True. Ctrl-C, SIGTERM, SIGHUP or the end of standard
    input: False. The stop signals raise here while it waits (a handler that only asks for an
    abort would leave the question waiting, and once answered, the machine moving); aborted()
    tells of one that came just before the question."""
    previous: dict[int, Any] = {}
    try:
        for sig in STOP_SIGNALS:  # inside the try: a signal as soon as one is in place
            previous[sig] = signal.signal(sig, _cancel)
        if aborted():
            return False
        print(prompt, file=sys.stderr, flush=True)
        return sys.stdin.readline() != ""
    except (KeyboardInterrupt, OSError):
        return False
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
