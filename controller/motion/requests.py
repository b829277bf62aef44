"""What an operator asks of a running motion controller: flags and values the loop reads each
cycle (safe from a signal handler or another thread: nothing here acts by itself)."""

from __future__ import annotations

import numpy as np

from controller.motion.source import row_lines


class OperatorRequests:
    """Hold, resume, feed override (and the M49/M48 lines it does not touch), abort."""

    _abort_message: str | None = None
    _resume_requested = False
    _hold_requested = False
    override_pct = 100.0
    override_off: list[tuple[int, int]] = []
    work_origin_mm: tuple[float, ...] = ()  # for the progress reports' work position
    held: np.ndarray
    line: int

    def request_resume(self) -> None:
        """Operator: continue after a program pause or a feed hold (a flag read by the loop)."""
        self._resume_requested = True

    def request_hold(self) -> None:
        """Operator: feed hold, a planned deceleration along the path to a standstill."""
        self._hold_requested = True

    def set_override_off_lines(self, spans: list[list[int]]) -> None:
        """M49 ... M48 stretches [first, last] (last -1: to the end): lines run at 100 %."""
        self.override_off = [(a, b if b >= 0 else 1 << 62) for a, b in spans]

    def _override_allowed(self) -> bool:
        if not self.override_off:
            return True
        line = int(row_lines(self.held[:1])[0]) if len(self.held) else self.line
        return not any(a <= line < b for a, b in self.override_off)

    def set_feed_override(self, percent: float) -> None:
        """Operator: feed override in % of the planned feed, 0-150 (0 holds; above 100 only
        as far as the rows ahead allow within Vmax, Amax and the contour limit)."""
        self.override_pct = min(max(float(percent), 0.0), 150.0)

    def request_abort(self, message: str = "aborted by operator") -> None:
        """Operator stop (SIGINT handler safe: only sets a flag read by the loop)."""
        self._abort_message = message

    estop_message: str | None = None

    def request_estop(self, message: str = "e-stop") -> None:
        """Operator e-stop (category 1): the fastest stop along the path within Amax, then
        the drives disabled until reset (a flag read by the loop)."""
        self.estop_message = message

    @property
    def abort_requested(self) -> bool:
        return self._abort_message is not None or self.estop_message is not None
