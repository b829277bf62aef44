"""The three-process runtime: shm ring, back-pressure, and a crash of any process -> stop."""

from __future__ import annotations

import os
import queue
import signal
import threading
import time

import numpy as np
import pytest
import refgen
from runtime_helpers import Recorder, assert_smooth, xy_config

from controller.motion.ring import FLAG_ABORT, FLAG_FAILED, RefRing
from controller.motion.source import SourceState
from controller.motion.types import MotionProgress, Outcome
from controller.runtime.processes import RingSource, Runtime, RuntimeOptions, _Messages
from drivers.sim.card import SimCard

CFG = xy_config()


def test_ring_wraps_and_keeps_row_order() -> None:
    ring = RefRing.create(8, 4)
    try:
        rows = np.arange(40.0).reshape(10, 4)
        assert ring.write(rows[:6]) and np.array_equal(ring.read(4), rows[:4])
        assert ring.write(rows[6:]) and ring.available() == 6
        assert np.array_equal(ring.read(100), rows[4:])
    finally:
        ring.close()


def test_ring_back_pressure_blocks_the_producer_until_read_or_abort() -> None:
    ring = RefRing.create(4, 1)
    try:
        done: list[bool] = []
        writer = threading.Thread(target=lambda: done.append(ring.write(np.ones((10, 1)))))
        writer.start()
        time.sleep(0.05)
        assert ring.available() == 4 and not done  # full: the producer waits
        ring.read(4)
        time.sleep(0.05)
        ring.set_flag(FLAG_ABORT)
        writer.join(1.0)
        assert done == [False] and ring.written == 8
    finally:
        ring.close()


def run_rt(virtual: bool, blocks_fn: object = refgen.fake_blocks,
           generate_fn: object = refgen.fake_generate, kill_at_s: float | None = None,
           ring_s: float | None = None) -> tuple[object, Runtime, Recorder, dict]:
    card = SimCard(CFG, realtime=not virtual)
    rec = Recorder(card)
    seen: dict = {}
    runtime: Runtime

    def progress(p: MotionProgress) -> None:
        if kill_at_s is not None and p.executed_s >= kill_at_s and "killed" not in seen:
            seen["killed"] = time.monotonic()
            os.kill(runtime.procs["generator"].pid, signal.SIGKILL)
        if "killed" in seen and p.state.value == "stopping" and "stopping" not in seen:
            seen["stopping"] = time.monotonic()

    opts = RuntimeOptions(virtual_time=virtual, blocks_fn=blocks_fn, generate_fn=generate_fn,
                          drive=card, on_progress=progress, ring_seconds=ring_s,
                          settings={"progress_every_s": 0.002})
    runtime = Runtime("test.nc", CFG, opts)
    return runtime.run(), runtime, rec, seen


@pytest.mark.parametrize("virtual", [True, False])
def test_three_processes_run_a_circle_exactly(virtual: bool) -> None:
    result, runtime, rec, _ = run_rt(virtual)
    assert result.outcome is Outcome.DONE, result.message
    assert result.final_position_mm == {"x": 0.0, "y": 0.0} and result.underruns == 0
    assert result.commanded_counts == result.executed_counts
    assert set(result.extra["peak_rss_mb"]) == {"interpreter", "generator", "motion"}
    assert all(not p.is_alive() for p in runtime.procs.values())


@pytest.mark.parametrize("virtual", [True, False])
def test_killing_the_generator_stops_the_table_without_underrun(virtual: bool) -> None:
    # A ring of 0.3 s: the 0.4 s streamed before the hang fill it, so the job starts moving.
    result, _, rec, seen = run_rt(virtual, generate_fn=refgen.hanging_generate, kill_at_s=0.15,
                                  ring_s=0.3)
    assert "killed" in seen
    assert result.outcome is Outcome.FAULT and "generator process died" in result.message
    assert result.underruns == 0 and result.position_known
    assert result.commanded_counts == result.executed_counts
    assert_smooth(rec.commanded(), np.zeros(2), CFG)
    assert seen["stopping"] - seen["killed"] < 0.1  # detected within 100 ms


def test_generator_error_is_reported_by_name() -> None:
    result, _, rec, _ = run_rt(True, blocks_fn=refgen.many_blocks,
                               generate_fn=refgen.failing_generate)
    assert result.outcome is Outcome.FAULT
    assert "PlanningError: contour error 41 um" in result.message
    assert result.underruns == 0 and result.commanded_counts == result.executed_counts


def test_interpreter_crash_is_detected_and_stops_under_control() -> None:
    result, _, rec, _ = run_rt(False, blocks_fn=refgen.crashing_blocks,
                               generate_fn=refgen.per_block_generate)
    assert result.outcome is Outcome.FAULT
    assert "NC interpreter process died (exit code 9)" in result.message
    assert result.underruns == 0 and result.commanded_counts == result.executed_counts
    assert_smooth(rec.commanded(), np.zeros(2), CFG)


def test_operator_abort_stops_all_processes() -> None:
    card = SimCard(CFG, realtime=True)
    runtime = Runtime("t.nc", CFG, RuntimeOptions(blocks_fn=refgen.fake_blocks,
                                                  generate_fn=refgen.paced_generate, drive=card))
    threading.Timer(0.3, runtime.request_abort).start()
    result = runtime.run()
    assert result.outcome is Outcome.ABORTED and result.underruns == 0
    assert result.commanded_counts == result.executed_counts
    assert all(not p.is_alive() for p in runtime.procs.values())


def test_interpreter_error_mid_run_is_reported_with_its_location() -> None:
    result, _, rec, _ = run_rt(True, blocks_fn=refgen.erroring_blocks,
                               generate_fn=refgen.per_block_generate)
    assert result.outcome is Outcome.FAULT
    assert "NC interpreter failed: test.nc:12:5: error: unknown G-code G5" in result.message
    assert result.underruns == 0 and result.commanded_counts == result.executed_counts
    assert_smooth(rec.commanded(), np.zeros(2), CFG)


class _CountingQueue:
    """The info queue's get(), counting the waits that found nothing."""

    def __init__(self, items: list[tuple]) -> None:
        self.items, self.empty_waits = list(items), 0

    def get(self, timeout: float) -> tuple:
        if self.items:
            return self.items.pop(0)
        if timeout > 0:
            self.empty_waits += 1
        raise queue.Empty


def test_drain_stops_waiting_once_the_awaited_message_is_in() -> None:
    q = _CountingQueue([("error", "interpreter", "t.nc:3:1: error"), ("rss_kb", "interpreter", 9)])
    messages = _Messages(q)
    t0 = time.monotonic()
    messages.drain(30.0, until=lambda: "interpreter" in messages.rss_kb)
    assert time.monotonic() - t0 < 5.0 and q.empty_waits == 0
    assert messages.errors == {"interpreter": "t.nc:3:1: error"}


def test_an_interpreter_error_that_arrives_after_the_generators_still_names_its_line() -> None:
    # Each stage's messages go through its own queue feeder thread: on a loaded machine the
    # generator's "input failed" (and its last message) can be in before the interpreter's
    # error. The stop is not held up for it; the result's message is completed at the end.
    q = _CountingQueue([("error", "generator", "RuntimeError: NC interpreter failed"),
                        ("rss_kb", "generator", 9)])
    messages = _Messages(q)
    stop_reason = messages.failure()
    assert stop_reason == "RuntimeError: NC interpreter failed"
    q.items += [("error", "interpreter", "t.nc:12:5: error: unknown G-code G5"),
                ("rss_kb", "interpreter", 9)]
    messages.drain(0.0)
    final = messages.final(f"{stop_reason}, then card FIFO underrun")
    assert final == ("NC interpreter failed: t.nc:12:5: error: unknown G-code G5, "
                     "then card FIFO underrun")
    assert messages.final("following error on X") == "following error on X"


def test_a_dead_interpreter_is_waited_for_once_not_on_every_cycle_of_the_stop() -> None:
    class Dead:
        exitcode = 9

    runtime = Runtime("t.nc", CFG, RuntimeOptions())
    runtime.procs["interpreter"] = Dead()  # type: ignore[assignment]
    q = _CountingQueue([])
    watch = runtime._watch(_Messages(q))
    problems = [watch() for _ in range(20)]  # the motion loop asks every cycle
    assert problems == ["NC interpreter process died (exit code 9)"] * 20
    assert q.empty_waits == 1


def test_a_failed_stream_is_waited_for_once() -> None:
    ring = RefRing.create(8, 4)
    try:
        ring.set_flag(FLAG_FAILED)
        q = _CountingQueue([])
        source = RingSource(ring, None, _Messages(q))
        states = [source.state() for _ in range(20)]
        assert states == [(SourceState.FAILED, "reference generator failed")] * 20
        assert q.empty_waits == 1
    finally:
        ring.close()


def test_a_producer_has_a_memory_ceiling() -> None:
    """A planning bug ends one job with MemoryError, not the PC (a 1e20 s dwell once grew
    the generator to 4 GB)."""
    import subprocess
    import sys

    code = ("import resource\nfrom controller.runtime.stages import _data_bytes, memory_ceiling\n"
            "held = bytearray(300 << 20)  # a big parent: what it holds is not counted\n"
            "memory_ceiling(256 << 20)\n"
            "print(resource.getrlimit(resource.RLIMIT_DATA)[0] - _data_bytes() <= 256 << 20)\n"
            "more = bytearray(128 << 20)\n"
            "try:\n    b = bytearray(512 << 20)\nexcept MemoryError:\n    print('refused')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.stdout.split() == ["True", "refused"], done.stderr
