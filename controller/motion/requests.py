"""What an operator asks of a running motion controller: flags and values the loop reads each
cycle (safe from a signal handler or another thread: nothing here acts by itself)."""

from __future__ import annotations


class OperatorRequests:
    """Hold, resume, feed override (and the M49/M48 lines it does not touch), abort, e-stop:
    set by the operator's side, read (and the one-shot flags cleared) by the motion loop."""

    def __init__(self) -> None:
        self.abort_message: str | None = None
        self.estop_message: str | None = None
        self.resume = False  # a resume asked, not yet acted on
        self.hold = False  # a feed hold asked, not yet acted on
        self.override_pct = 100.0
        self.override_off: list[tuple[int, int]] = []

    def request_resume(self) -> None:
        """Operator: continue after a program pause or a feed hold (a flag read by the loop)."""
        self.resume = True

    def request_hold(self) -> None:
        """Operator: feed hold, a planned deceleration along the path to a standstill."""
        self.hold = True

    def set_override_off_lines(self, spans: list[list[int]]) -> None:
        """M49 ... M48 stretches [first, last] (last -1: to the end): lines run at 100 %."""
        self.override_off = [(a, b if b >= 0 else 1 << 62) for a, b in spans]

    def override_allowed(self, line: int) -> bool:
        """Whether the override applies at this program line (not within M49 ... M48)."""
        return not any(a <= line < b for a, b in self.override_off)

    def set_feed_override(self, percent: float) -> None:
        """Operator: feed override in % of the planned feed, 0-150 (0 holds; above 100 only
        as far as the rows ahead allow within Vmax, Amax and the contour limit)."""
        self.override_pct = min(max(float(percent), 0.0), 150.0)

    def request_abort(self, message: str = "aborted by operator") -> None:
        """Operator stop (SIGINT handler safe: only sets a flag read by the loop)."""
        self.abort_message = message

    def request_estop(self, message: str = "e-stop") -> None:
        """Operator e-stop (category 1): the fastest stop along the path within Amax, then
        the drives disabled until reset (a flag read by the loop)."""
        self.estop_message = message

    @property
    def abort_requested(self) -> bool:
        return self.abort_message is not None or self.estop_message is not None
