"""The loop clocking the sim card a block a cycle (virtual time) does what it does cycle by cycle:
the same frames, the same figures, a fault inside a block stopped from the frame it shows in."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from refgen import circle_chunks
from runtime_helpers import Recorder, assert_smooth, virtual_card

from controller.config import MachineConfig, load_config
from controller.motion.loop import ESTOP_KEEP_MS, MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.source import ChunkSource
from controller.motion.types import MotionProgress, MotionResult, MotionSettings, Outcome


def tight(config: MachineConfig) -> MachineConfig:
    """A following-error limit the circle's own lag crosses while it speeds up (no injection:
    the trip's frame is the motion's, whichever way the card is clocked)."""
    axes = tuple(replace(a, ferror_mm=0.05, min_ferror_mm=0.01) for a in config.axes)
    return replace(config, axes=axes)


def run(
    config: MachineConfig, blocks: bool, estop_at_s: float | None = None
) -> tuple[MotionResult, np.ndarray, list[int]]:
    """A run of the circle; the frames executed; the frames each clocking of the card ran
    (an e-stop asked: the frames executed when it was asked, last)."""
    card = virtual_card(config)
    rec = Recorder(card)
    clocked: list[int] = []

    def advance(n: int) -> None:
        clocked.append(n)
        card.advance(n)

    def advance_until(n: int, cut: object, step: int) -> int:
        clocked.append(card.advance_until(n, cut, step))  # type: ignore[arg-type]
        return clocked[-1]

    pacer = VirtualPacer(
        2, config.sample_period_s, advance, advance_until=advance_until if blocks else None
    )
    ctrl: MotionController

    asked: list[int] = []
    stopping: list[int] = []  # the frames executed when the loop began its stop

    def progress(p: MotionProgress) -> None:
        if p.state.value == "stopping" and not stopping:
            stopping.append(round(p.executed_s / config.sample_period_s))
        if estop_at_s is not None and p.executed_s >= estop_at_s and not asked:
            asked.append(ctrl.figures.executed)
            ctrl.request_estop("e-stop by operator")

    settings = MotionSettings.from_config(config, progress_every_s=0.002)
    ctrl = MotionController(
        config, card, ChunkSource(list(circle_chunks())), pacer, settings, on_progress=progress
    )
    result = ctrl.run()
    result.extra["stopping_at"] = stopping[0] if stopping else None
    return result, rec.commanded(), clocked + asked


def same_stop(
    cycles: MotionResult, frames_c: np.ndarray, blocks: MotionResult, frames_b: np.ndarray
) -> None:
    """The stop began at the same frame, and every frame up to it is the same. The stop is
    queued behind the frames in the card (no take-back for a fault), and a block run's FIFO
    holds up to a block less: it ends that much sooner along the same path."""
    at = cycles.extra["stopping_at"]
    assert at is not None and blocks.extra["stopping_at"] == at
    n = min(len(frames_b), len(frames_c))
    differ = np.flatnonzero(np.any(frames_b[:n] != frames_c[:n], axis=1))
    assert (differ[0] if differ.size else n) >= at
    assert abs(len(frames_b) - len(frames_c)) <= 64


@pytest.mark.parametrize("name", ["xy_table_paper", "xy_table"])  # without, with pre-compensation
def test_a_run_in_blocks_is_the_run_cycle_by_cycle(name: str) -> None:
    config = load_config(name)
    cycles, frames_c, clock_c = run(config, blocks=False)
    blocks, frames_b, clock_b = run(config, blocks=True)
    assert max(clock_c) == 2 and max(clock_b) > 2  # the blocks were clocked
    assert cycles.outcome is blocks.outcome is Outcome.DONE
    assert np.array_equal(frames_b, frames_c)
    assert blocks.final_position_mm == cycles.final_position_mm
    assert blocks.motion_time_s == cycles.motion_time_s
    assert blocks.settling_time_s == cycles.settling_time_s
    assert blocks.time_to_first_motion_s == pytest.approx(cycles.time_to_first_motion_s)
    for key in ("max", "rms", "mean"):
        assert blocks.contour_error_um[key] == pytest.approx(cycles.contour_error_um[key], abs=1e-6)


def test_a_following_error_inside_a_block_stops_from_its_own_cycle() -> None:
    config = tight(load_config("xy_table_paper"))
    cycles, frames_c, _ = run(config, blocks=False)
    blocks, frames_b, clock_b = run(config, blocks=True)
    assert cycles.outcome is Outcome.FAULT and "following error" in cycles.message
    assert blocks.message == cycles.message  # the same axis, error, limit and line
    assert any(n not in (2, 64) for n in clock_b)  # a block cut short at the fault's cycle
    same_stop(cycles, frames_c, blocks, frames_b)
    assert blocks.position_known and blocks.underruns == 0
    assert_smooth(frames_b, np.zeros(2), config)


def test_an_implausible_reading_inside_a_block_stops_from_its_own_cycle() -> None:
    """X's travel ends at 15 mm (and its 1 mm of slack) on the way round the 20 mm circle: an
    encoder reading off the travel is one no drive could give, seen at the same frame."""
    config = load_config("xy_table_paper")
    axes = (replace(config.axes[0], travel_mm=(-150.0, 15.0)), *config.axes[1:])
    config = replace(config, axes=axes)
    cycles, frames_c, _ = run(config, blocks=False)
    blocks, frames_b, clock_b = run(config, blocks=True)
    assert cycles.outcome is Outcome.FAULT and "off its travel" in cycles.message
    assert blocks.message == cycles.message and not blocks.position_known
    assert any(n not in (2, 64) for n in clock_b)  # a block cut short at the reading's cycle
    same_stop(cycles, frames_c, blocks, frames_b)


@pytest.mark.parametrize("name", ["xy_table_paper", "xy_table"])
def test_an_estop_after_blocks_takes_back_all_but_two_frames(name: str) -> None:
    """Blocks go out as cycle-sized sends in the journal: the e-stop keeps ESTOP_KEEP_MS queued,
    as after cycle-sized refills, so the stop starts as soon (pre-compensated: its lead's
    settling follows the stop, as cycle by cycle)."""
    config = load_config(name)
    cycles, frames_c, clock_c = run(config, blocks=False, estop_at_s=0.4)
    blocks, frames_b, clock_b = run(config, blocks=True, estop_at_s=0.4)
    assert max(clock_b[:-1]) > 2 and blocks.outcome is cycles.outcome is Outcome.ABORTED
    assert len(frames_b) - clock_b[-1] == len(frames_c) - clock_c[-1]
    if not config.interpolator.servo_precompensation:
        v_mm_s, accel = 58.333, config.interpolator.max_accel_mm_s2
        stop_frames = int(np.ceil(v_mm_s / accel / config.sample_period_s))
        # The cycle's own 2 frames, those kept, the stop at Amax (as tests/motion/test_estop).
        kept = int(np.ceil(ESTOP_KEEP_MS * 1e-3 / config.sample_period_s - 1e-9))
        assert len(frames_b) - clock_b[-1] <= 2 + kept + stop_frames + 3
        assert_smooth(frames_b, np.zeros(2), config)  # the lead is not within Amax
