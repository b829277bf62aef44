"""WallPacer: absolute deadlines, late cycles counted, set-up before the loop not counted."""

from __future__ import annotations

import time

from controller.motion.pacing import WallPacer


def test_set_up_before_the_first_cycle_is_not_a_late_cycle() -> None:
    pacer = WallPacer(0.002)
    time.sleep(0.03)  # the loop's set-up: reading the drives' positions, building filters
    pacer.wait()
    assert pacer.late_cycles == 0
    assert pacer.max_late_s < 0.002


def test_a_stall_inside_the_loop_is_counted_once_and_not_made_up() -> None:
    pacer = WallPacer(0.002)
    pacer.wait()
    time.sleep(0.03)  # a stall of 15 cycles
    pacer.wait()
    assert pacer.late_cycles == 1
    assert pacer.max_late_s >= 0.025
    t0 = time.monotonic()
    pacer.wait()  # re-anchored: the next cycle comes a cycle later, not at once to catch up
    assert time.monotonic() - t0 >= 0.0015


def test_cycles_are_never_early() -> None:
    pacer = WallPacer(0.002)
    pacer.wait()
    t0 = time.monotonic()
    for _ in range(50):
        pacer.wait()
    elapsed_s = time.monotonic() - t0
    assert elapsed_s >= 0.098  # absolute deadlines: never early (late only by load)
