"""Motion-loop pacing: wall-clock cycles (counting late wake-ups) or virtual time for tests."""

from __future__ import annotations

import time
from collections.abc import Callable

from drivers.base import Feedback

AdvanceUntil = Callable[[int, Callable[[Feedback], int | None], int], int]


class WallPacer:
    """Absolute-deadline cycles on CLOCK_MONOTONIC; a wake-up a whole cycle late is counted.

    A late cycle is not made up by running twice: the card FIFO absorbs it, and the refill
    after it simply writes more frames.
    """

    def __init__(self, cycle_s: float) -> None:
        self.cycle_s = cycle_s
        self.late_cycles = 0
        self.max_late_s = 0.0
        self._deadline_s: float | None = None  # anchored by the first wait
        self._start_s = time.monotonic()

    def wait(self) -> None:
        if self._deadline_s is None:
            # The first cycle runs at once: the set-up between making the pacer and the loop
            # (reading the drives' positions, over SDO on a CANopen bus) is not a late cycle.
            self._deadline_s = time.monotonic()
            return
        self._deadline_s += self.cycle_s
        delay_s = self._deadline_s - time.monotonic()
        if delay_s > 0:
            time.sleep(delay_s)
        late_s = time.monotonic() - self._deadline_s
        self.max_late_s = max(self.max_late_s, late_s)
        if late_s > self.cycle_s:
            self.late_cycles += 1
            self._deadline_s = time.monotonic()  # re-anchor instead of bursting to catch up

    def elapsed_s(self) -> float:
        return time.monotonic() - self._start_s

    def idle(self) -> None:
        """The machine waits for the operator (M0, a hold): wall-clock cycles already sleep."""


class VirtualPacer:
    """Each wait() advances simulated time by one cycle by calling `advance(frames)`."""

    def __init__(self, cycle_frames: int, period_s: float, advance: Callable[[int], None],
                 ready: Callable[[], bool] | None = None,
                 advance_until: AdvanceUntil | None = None) -> None:
        self.cycle_s = cycle_frames * period_s
        self.cycle_frames = cycle_frames
        self.late_cycles = 0
        self.max_late_s = 0.0
        self._advance = advance
        # A card that clocks a block and takes back what follows a fault in it (SimCard.
        # advance_until): the loop may then clock a block a cycle (see motion/blocks.py).
        self._advance_until = advance_until
        # Virtual time stands still until the producers are ahead (or finished, or dead):
        # a slow generator never looks like a starved one here.
        self._ready = ready
        self._cycles = 0
        self.stall_cycles = 0  # test hook: the next n cycles are "late" (host stalled)

    @property
    def blocks(self) -> bool:
        """Whether wait_block can clock more than a cycle."""
        return self._advance_until is not None and not self.stall_cycles

    def wait(self) -> None:
        self._wait_ready()
        steps = 1 + self.stall_cycles
        if self.stall_cycles:
            self.late_cycles += 1
            self.stall_cycles = 0
        self._advance(self.cycle_frames * steps)
        self._cycles += steps

    def wait_block(self, frames: int, cut: Callable[[Feedback], int | None]) -> int:
        """Up to `frames` periods (whole cycles) at once; fewer when cut finds in the block's
        feedback a row the loop had to act on (the cycle holding it ends the block). Returns
        the periods clocked."""
        if self._advance_until is None:
            self.wait()
            return self.cycle_frames
        self._wait_ready()
        clocked = self._advance_until(frames, cut, self.cycle_frames)
        self._cycles += clocked // self.cycle_frames
        return clocked

    def _wait_ready(self) -> None:
        # Each look costs the motion process CPU (the ring, the producers' exit codes): a
        # producer behind is looked at less and less often, up to READY_POLL_MAX_S apart.
        pause_s = READY_POLL_S
        while self._ready is not None and not self._ready():
            time.sleep(pause_s)
            pause_s = min(2 * pause_s, READY_POLL_MAX_S)

    def elapsed_s(self) -> float:
        return self._cycles * self.cycle_s

    def idle(self) -> None:
        """The machine waits for the operator (M0, a hold): nothing to simulate, so the cycle
        gives its core back (it spun at 94 % of one while waiting)."""
        time.sleep(IDLE_SLEEP_S)


IDLE_SLEEP_S = 0.001
READY_POLL_S = 0.0002
READY_POLL_MAX_S = 0.002
