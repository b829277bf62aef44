"""Motion controller in virtual time: streaming, water marks, following error, controlled stops."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from refgen import circle_chunks, line_chunks
from runtime_helpers import Recorder, assert_smooth, virtual_card, xy_config

from controller.motion.checks import FerrorCheck
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.source import ChunkSource, chunk_rows
from controller.motion.types import (
    MotionProgress,
    MotionResult,
    MotionSettings,
    MotionState,
    Outcome,
)
from controller.servo.model import discretise, tracking_error_mm
from controller.servo.true_distance import distance_from_reference_mm
from drivers.base import CardStatus

CFG = xy_config()
T = CFG.sample_period_s
Inject = Callable[[object, MotionController, VirtualPacer], None]


def run(chunks: list, inject: Inject | None = None, at_s: float = 0.3,
        source_kw: dict | None = None, **overrides: float) -> tuple[MotionResult, object,
                                                                    Recorder, list]:
    card = virtual_card(CFG)
    rec = Recorder(card)
    pacer = VirtualPacer(2, T, card.advance)
    seen: list[MotionProgress] = []
    ctrl: MotionController

    def progress(p: MotionProgress) -> None:
        seen.append(p)
        if inject is not None and p.executed_s >= at_s and not getattr(ctrl, "_injected", 0):
            ctrl._injected = 1  # type: ignore[attr-defined]
            inject(card, ctrl, pacer)

    s = MotionSettings.from_config(CFG, progress_every_s=0.002, **overrides)
    ctrl = MotionController(CFG, card, ChunkSource(chunks, **(source_kw or {})), pacer, s,
                            on_progress=progress)
    return ctrl.run(), card, rec, seen


def accounted(result: MotionResult, card: object) -> None:
    """No pulse lost: commanded = executed + whatever the card still held (discarded by reset)."""
    card.reset()  # type: ignore[attr-defined]
    executed = np.array(list(result.executed_counts.values()))
    commanded = np.array(list(result.commanded_counts.values()))
    assert np.array_equal(commanded, executed + card.discarded_counts)  # type: ignore[attr-defined]


def on_circle(result: MotionResult, radius_mm: float = 10.0, tol_mm: float = 0.01) -> None:
    p = np.array([result.final_position_mm["x"], result.final_position_mm["y"]])
    assert abs(np.linalg.norm(p - [radius_mm, 0.0]) - radius_mm) < tol_mm


def predicted_contour_um(chunks: list) -> tuple[float, float]:
    """Offline prediction (servo model over the whole reference and 60 ms of settling), as
    `cncctl simulate` does: the tool's distance from the path, what the run measures too. The
    circle's quintic braking at Amax overshoots its end by about 50 um (nothing shaped it)."""
    pos = np.vstack([c.pos_mm for c in chunks])
    held = np.vstack([pos, np.repeat(pos[-1:], 60, axis=0)])
    v = np.diff(held, axis=0, prepend=held[:1]) / T
    e = np.column_stack([tracking_error_mm(discretise(a.servo, T), v[:, i])
                         for i, a in enumerate(CFG.axes)])
    eps = distance_from_reference_mm(held, held - e)
    return float(eps.max() * 1e3), float(np.sqrt(np.mean(eps[: len(pos)] ** 2)) * 1e3)


def test_circle_runs_to_the_pulse_and_matches_the_servo_prediction() -> None:
    chunks = list(circle_chunks())
    result, card, rec, _ = run(chunks)
    assert result.outcome is Outcome.DONE and result.underruns == 0
    assert result.final_position_mm == {"x": 0.0, "y": 0.0}
    assert result.commanded_counts == result.executed_counts
    assert result.planned_time_s == pytest.approx(sum(len(c) for c in chunks) * T)
    max_um, rms_um = predicted_contour_um(chunks)
    assert result.contour_error_um["max"] == pytest.approx(max_um, rel=0.1, abs=2.0)
    assert result.contour_error_um["rms"] == pytest.approx(rms_um, rel=0.1, abs=2.0)
    assert_smooth(rec.commanded(), np.zeros(2), CFG)


@pytest.mark.parametrize("low_ms,high_ms", [(20.0, 100.0), (40.0, 60.0)])
def test_fifo_stays_between_the_water_marks(low_ms: float, high_ms: float) -> None:
    result, _, _, seen = run(list(circle_chunks()), low_water_ms=low_ms, high_water_ms=high_ms)
    assert result.outcome is Outcome.DONE
    running = [p.fifo_ms for p in seen if p.state.value == "running" and p.executed_s > 0.05]
    assert max(running) <= high_ms
    assert low_ms <= result.min_fifo_ms <= high_ms


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-150, 150), st.floats(-150, 150)), min_size=1, max_size=5))
def test_ferror_limit_is_the_linuxcnc_rule(v: list) -> None:
    check = FerrorCheck(CFG, np.zeros(2, dtype=np.int64))
    limits = check.limits_mm(np.array(v))
    expected = [[a.ferror_limit_mm(row[i]) for i, a in enumerate(CFG.axes)] for row in v]
    assert np.allclose(limits, expected)


def test_small_lag_at_low_speed_does_not_trip() -> None:
    chunks = list(line_chunks((3.0, 0.0), v_mm_s=5.0))
    result, _, _, _ = run(chunks, inject=lambda c, *_: c.inject_lag(0, 0.2), at_s=0.1)
    assert result.outcome is Outcome.DONE, result.message
    assert 190.0 <= result.following_error_um_max < 250.0


@pytest.mark.parametrize("fault", ["lag", "stall"])
def test_following_error_trips_into_a_controlled_stop(fault: str) -> None:
    def inject(card: object, ctrl: MotionController, pacer: VirtualPacer) -> None:
        if fault == "lag":
            card.inject_lag(1, 0.6)  # type: ignore[attr-defined]
        else:
            card.inject_stall(1)  # type: ignore[attr-defined]
    result, card, rec, _ = run(list(circle_chunks()), inject=inject)
    assert result.outcome is Outcome.FAULT
    assert result.message.startswith("Y axis following error") and "at line 3" in result.message
    assert result.underruns == 0 and result.position_known
    assert result.commanded_counts == result.executed_counts
    assert_smooth(rec.commanded(), np.zeros(2), CFG)


def test_drive_fault_latches_with_its_message_and_pulses_accounted() -> None:
    result, card, _, _ = run(list(circle_chunks()),
                             inject=lambda c, *_: c.inject_drive_fault(0, 0x2310))
    assert result.outcome is Outcome.FAULT and result.message == "X axis drive fault 0x2310"
    assert result.position_known
    assert result.commanded_counts != result.executed_counts  # the card halted with frames
    accounted(result, card)


def test_operator_abort_decelerates_along_the_path() -> None:
    result, card, rec, _ = run(list(circle_chunks()),
                               inject=lambda c, ctrl, p: ctrl.request_abort(), at_s=0.4)
    assert result.outcome is Outcome.ABORTED and result.underruns == 0
    assert result.commanded_counts == result.executed_counts
    on_circle(result, tol_mm=0.002)  # stopped on the path, not on a tangent
    assert_smooth(rec.commanded(), np.zeros(2), CFG)


@pytest.mark.parametrize("kw,needle", [({"starve_after_rows": 500}, "feed hold"),
                                        ({"fail_after_rows": 500}, "process died")])
def test_late_or_dead_generator_stops_without_underrun(kw: dict, needle: str) -> None:
    result, card, rec, _ = run(list(circle_chunks()), source_kw=kw)
    assert result.outcome is Outcome.FAULT and needle in result.message
    assert result.underruns == 0 and result.commanded_counts == result.executed_counts
    on_circle(result, tol_mm=0.002)
    assert_smooth(rec.commanded(), np.zeros(2), CFG)


def test_stalled_host_underruns_and_the_card_latches() -> None:
    def stall(card: object, ctrl: MotionController, pacer: VirtualPacer) -> None:
        pacer.stall_cycles = 100  # the motion process slept 200 ms
    result, card, _, _ = run(list(circle_chunks()), inject=stall)
    assert result.outcome is Outcome.FAULT and "underrun" in result.message
    assert result.underruns == 1 and result.late_cycles >= 1
    accounted(result, card)


def test_a_card_halting_between_status_and_write_is_a_fault_with_a_result() -> None:
    """The card latches (here an underrun, as after the host stalled) after the cycle read its
    status and before it writes: the write raised UnderrunError out of the loop, and a run
    ended with no result and no position (1 in 12 stalls from outside, a cncd job's journal
    left RUNNING). Now it is the same fault as one read at the cycle's start."""
    def halt_at_next_write(card: object, ctrl: MotionController, pacer: VirtualPacer) -> None:
        original = card._send_frames  # type: ignore[attr-defined]

        def send(frames: np.ndarray, end_of_stream: bool) -> None:
            card._latch(CardStatus.UNDERRUN, "card FIFO underrun: frames ran out")  # type: ignore[attr-defined]
            card._send_frames = original  # type: ignore[attr-defined]
            original(frames, end_of_stream)
        card._send_frames = send  # type: ignore[attr-defined]
    result, card, _, _ = run(list(circle_chunks()), inject=halt_at_next_write)
    assert result.outcome is Outcome.FAULT and "underrun" in result.message
    assert result.position_known and result.underruns == 1
    accounted(result, card)


def test_lost_communication_is_a_fault_and_the_card_stops_itself() -> None:
    result, card, _, _ = run(list(circle_chunks()), inject=lambda c, *_: c.inject_lost_comm())
    assert result.outcome is Outcome.FAULT and "lost communication" in result.message
    assert not result.position_known
    card.advance(200)  # the card runs its FIFO dry and latches, as hostmot2 would
    card.restore_comm()
    cmd, _ = card.position_counts()
    assert np.array_equal(cmd, list(result.commanded_counts.values()))


def test_reference_not_starting_at_the_machine_position_is_refused() -> None:
    chunks = list(line_chunks((5.0, 0.0), start_mm=(1.0, 0.0)))
    result, _, rec, _ = run(chunks)
    assert result.outcome is Outcome.FAULT and "machine is at" in result.message
    assert result.commanded_counts == {"x": 0, "y": 0} and not rec.parts[-1].seq.size


def test_chunk_rows_layout() -> None:
    chunk = next(iter(line_chunks((1.0, 2.0))))
    rows = chunk_rows(chunk)
    assert rows.shape == (len(chunk), 4) and np.all(rows[:, 3] == 2)


def _m0_chunks() -> list:
    import tempfile

    from controller.generator.plan import generate_reference
    from controller.interpreter.program import read_program
    with tempfile.TemporaryDirectory() as tmp:
        program = Path(tmp) / "m0.nc"
        program.write_text("G21 G90 G64 F2400\nG1 X10\nG1 Y10\nM0\nG1 X0\nG1 Y0\nM2\n")
        return list(generate_reference(read_program(str(program), CFG), CFG))


def _run_with_pause(on_paused: str) -> tuple:
    card = virtual_card(CFG)
    settings = MotionSettings.from_config(CFG)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    seen: list = []

    def progress(p) -> None:
        seen.append(p)
        if p.state is MotionState.PAUSED and sum(s.state is MotionState.PAUSED for s in seen) == 5:
            getattr(ctrl, on_paused)()
    ctrl = MotionController(CFG, card, ChunkSource(_m0_chunks()), pacer, settings,
                            on_progress=progress)
    return ctrl.run(), seen, card


def test_m0_pauses_at_rest_and_resumes_on_the_path() -> None:
    result, seen, _ = _run_with_pause("request_resume")
    states = [s.state for s in seen]
    assert MotionState.PAUSED in states
    first = states.index(MotionState.PAUSED)
    assert MotionState.RUNNING in states[first:]  # it went on after the resume
    paused = [s for s in seen if s.state is MotionState.PAUSED]
    assert all(p.line == 4 and p.feed_mm_s == 0.0 and p.fifo_ms == 0.0 for p in paused)
    assert result.outcome is Outcome.DONE and result.underruns == 0
    assert result.final_position_mm == {"x": 0.0, "y": 0.0}
    assert result.commanded_counts == result.executed_counts
    assert result.min_fifo_ms > 0.0  # the empty FIFO of the pause is not counted


def test_abort_while_paused_ends_at_once_at_rest() -> None:
    result, seen, _ = _run_with_pause("request_abort")
    assert result.outcome is Outcome.ABORTED
    assert result.final_position_mm == {"x": 10.0, "y": 10.0}
    assert result.commanded_counts == result.executed_counts


def test_program_without_motion_ends_at_once() -> None:
    result, _, rec, _ = run([])
    assert result.outcome is Outcome.DONE and result.motion_time_s == 0.0
    assert len(rec.commanded()) == 0


def test_corrupt_feedback_is_a_fault_with_the_position_unknown() -> None:
    """A flipped bit of the encoder reading (as on a noisy CAN link) read as 'Y axis
    following error 8388.608 mm' with the position 'known' at 232 mm on a 150 mm axis."""
    def flip(card: object, *_: object) -> None:
        real = card.feedback  # type: ignore[attr-defined]

        def flipped() -> object:
            fb = real()
            if len(fb):
                fb.encoder_counts[-1, 1] += 1 << 23
                card.feedback = real  # type: ignore[attr-defined]  (one bad reading)
            return fb
        card.feedback = flipped  # type: ignore[attr-defined]

    result, card, _, _ = run(list(circle_chunks()), inject=flip)
    assert result.outcome is Outcome.FAULT, result.message
    assert "Y axis encoder jumped 8388.6" in result.message and "unknown" in result.message
    assert not result.position_known
    assert abs(result.final_position_mm["y"]) < 20.0  # the last believed reading, on the circle


def test_the_first_point_may_be_a_period_at_amax_from_rest_but_no_further() -> None:
    from controller.motion.checks import start_gap

    pulse = np.array([0.001, 0.001])
    step = 0.5 * 2450.0 * 0.001 ** 2  # 1.225 um: a constant acceleration's first period
    here = np.array([100, -50])
    assert start_gap(np.array([0.1, -0.05]) + [step + 0.0009, 0.0], here, pulse, step) is None
    assert start_gap(np.array([0.1, -0.05]) + [step, 0.0], here, pulse) is not None  # quintic
    jump = start_gap(np.array([0.1, -0.05]) + [step + 0.0011, 0.0], here, pulse, step)
    assert jump is not None and "reference starts at" in jump
