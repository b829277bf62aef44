"""The Runtime now running of a sequence of them (an approach then the program, or a program a
stretch per probe): operator requests go to it, and an abort asked between two is kept."""

from __future__ import annotations

from controller.runtime.processes import Runtime


class CurrentRun:
    """Forwards hold, resume, feed override and abort to `current` when there is one."""

    def __init__(self) -> None:
        self.current: Runtime | None = None
        self.abort: str | None = None

    def request_hold(self) -> None:
        if self.current is not None:
            self.current.request_hold()

    def request_resume(self) -> None:
        if self.current is not None:
            self.current.request_resume()

    def set_feed_override(self, percent: float) -> None:
        if self.current is not None:
            self.current.set_feed_override(percent)

    def request_abort(self, message: str = "aborted by operator") -> None:
        self.abort = message
        if self.current is not None:
            self.current.request_abort(message)
