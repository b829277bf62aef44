"""Homing on the sim card (virtual time): switch found whatever the counters said, index, errors."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from controller.config import MachineConfig, load_config
from drivers.base import CardStatus
from drivers.errors import DriveError, HomingError
from drivers.homing import homing_groups, move_frames, trapezoid_counts
from drivers.sim.card import SimCard

CONFIG = load_config("xy_table_switches")  # X: -1 to the switch at -149, final -145; Y: +1, 149


def with_homing(config: MachineConfig, **changes: Any) -> MachineConfig:
    """The same machine with every homing section changed alike (None entries: no homing)."""
    axes = []
    for a in config.axes:
        h = a.homing
        axes.append(replace(a, homing=None if h is None else replace(h, **changes)))
    return replace(config, axes=tuple(axes))


def card(config: MachineConfig = CONFIG, **options: Any) -> SimCard:
    drive = SimCard(config, realtime=False, **options)
    drive.open()
    return drive


def counts(mm: list[float]) -> list[int]:
    return [round(v / 0.001) for v in mm]


def test_homing_finds_the_switches_whatever_the_counters_said() -> None:
    # The counters read (10, -20) at power-up; the table really stands at (-140, 140).
    drive = card(start_mm=[10.0, -20.0], true_start_mm=[-140.0, 140.0])
    assert drive.homed() == (False, False)
    assert np.allclose(drive.true_position_mm(), [-140.0, 140.0])
    drive.home([0, 1])
    cmd, enc = drive.position_counts()
    assert cmd.tolist() == counts([-145.0, 145.0]) and enc.tolist() == cmd.tolist()
    # The switches sit at home_mm: once homed the counters are the table's true position.
    assert np.allclose(drive.true_position_mm(), cmd * 0.001, atol=1e-6)
    assert drive.homed() == (True, True)
    assert len(drive.feedback()) == 0  # homing is not a stream: no feedback rows
    assert drive.status() == CardStatus.OK


def test_an_axis_starting_on_its_switch_backs_off_and_latches() -> None:
    drive = card(true_start_mm=[-149.5, 0.0])  # beyond X's switch edge (-149), on the switch
    drive.home([0])
    assert drive.position_counts()[0].tolist() == counts([-145.0, 0.0])
    assert abs(drive.true_position_mm()[0] + 145.0) < 1e-6
    assert drive.homed() == (True, False)


def test_a_switch_off_home_mm_shifts_the_frame_by_the_difference() -> None:
    # The switch really is 0.3 mm further out than the config says: the edge still reads
    # home_mm, so the counters are 0.3 mm off the simulated table's own frame.
    drive = card(true_start_mm=[0.0, 0.0], home_switch_mm=[-149.3, 149.0])
    drive.home([0, 1])
    assert drive.position_counts()[0].tolist() == counts([-145.0, 145.0])
    assert np.allclose(drive.true_position_mm(), [-145.3, 145.0], atol=1e-6)


def test_use_index_lands_on_the_index_mark_after_the_switch() -> None:
    cfg = with_homing(CONFIG, use_index=True)
    cfg = replace(cfg, axes=(replace(cfg.axes[0], homing=replace(
        cfg.axes[0].homing, home_mm=-148.6)), cfg.axes[1]))
    drive = card(cfg, true_start_mm=[-100.0, 100.0], index_pitch_mm=0.5)
    drive.home([0, 1])
    cmd, _ = drive.position_counts()
    assert cmd.tolist() == counts([-145.0, 145.0])
    # The point that reads home_mm is the first mark on from the switch edge (-148.6, moving
    # negative: -149.0; Y's edge 149.0 is a mark itself, so the next one: 149.5).
    found = drive.true_position_mm() - cmd * 0.001 + np.array([-148.6, 149.0])
    assert np.allclose(found, [-149.0, 149.5], atol=1e-6)


def test_a_missing_switch_is_a_homing_error_naming_the_axis() -> None:
    cfg = with_homing(CONFIG, search_mm_s=100.0)  # 330 mm of search in 3.3 s virtual
    drive = card(cfg, home_switch_mm=[-149.0, None])
    with pytest.raises(HomingError, match=r"Y axis homing failed: home switch not found "
                                          r"within 330\.0 mm") as err:
        drive.home([0, 1])
    assert err.value.axis == "y"
    assert drive.homed() == (False, False)  # X was stopped with it
    assert drive.status() == CardStatus.OK  # nothing latched: it can be tried again
    drive.home([0])
    assert drive.homed() == (True, False)


def test_homing_is_refused_while_frames_stream() -> None:
    drive = card()
    drive.write_frames(np.ones((10, 2), dtype=np.int64))  # a stream without its end
    with pytest.raises(HomingError, match="frames are streaming"):
        drive.home([0])
    drive.advance(11)  # ran out mid-stream: underrun, halted
    with pytest.raises(HomingError, match="halted.*reset"):
        drive.home([0])
    drive.reset()
    drive.write_frames(np.ones((10, 2), dtype=np.int64), end_of_stream=True)
    with pytest.raises(HomingError, match="streaming"):
        drive.home([0])
    drive.advance(20)
    drive.home([0])
    assert drive.homed() == (True, False)


def test_axes_without_homing_are_homed_and_cannot_be_homed() -> None:
    cfg = replace(CONFIG, axes=(CONFIG.axes[0], replace(CONFIG.axes[1], homing=None)))
    drive = card(cfg)
    assert drive.homed() == (False, True)
    with pytest.raises(HomingError, match="Y axis has no homing sequence configured"):
        drive.home([0, 1])
    with pytest.raises(HomingError, match="no axis 2"):
        drive.home([2])
    drive.home([])  # nothing to do
    assert homing_groups(cfg) == ((0,),)


def test_homed_is_lost_by_reopening_and_kept_by_homed_at_start() -> None:
    drive = card(true_start_mm=[-140.0, 140.0])
    drive.home([0, 1])
    drive.close()
    drive.open()
    assert drive.homed() == (False, False)
    assert card(homed_at_start=True).homed() == (True, True)


def test_a_time_out_stops_the_axes_and_says_so() -> None:
    drive = card(true_start_mm=[-100.0, 100.0])
    with pytest.raises(HomingError, match="X axis homing failed: time-out: not homed within "
                                          "0.5 s"):
        drive.home([0, 1], timeout_s=0.5)
    assert drive.homed() == (False, False)
    before, _ = drive.position_counts()
    drive.advance(50)
    assert np.array_equal(drive.position_counts()[0], before)  # stopped, not still searching


def test_drive_fault_during_homing_in_real_time() -> None:
    drive = SimCard(CONFIG, realtime=True, true_start_mm=[-100.0, 100.0])
    drive.open()
    errors: list[Exception] = []

    def home() -> None:
        try:
            drive.home([0, 1], timeout_s=10.0)
        except HomingError as exc:
            errors.append(exc)

    homing = threading.Thread(target=home)
    try:
        t0 = time.monotonic()
        homing.start()
        time.sleep(0.1)
        with pytest.raises(DriveError, match="frames refused: a homing sequence is running"):
            drive.write_frames(np.zeros((1, 2), dtype=np.int64))
        drive.inject_drive_fault(1)
        homing.join(timeout=5.0)
        assert time.monotonic() - t0 < 2.0
        assert len(errors) == 1 and errors[0].axis == "y"
        assert "drive fault during homing: Y axis drive fault 0x2310" in str(errors[0])
        assert CardStatus.FAULT in drive.status() and drive.homed() == (False, False)
    finally:
        homing.join(timeout=5.0)
        drive.close()


def test_after_homing_frames_stream_from_the_final_position() -> None:
    drive = card(true_start_mm=[-140.0, 140.0])
    drive.home([0, 1])
    drive.write_frames(np.tile([5, -5], (100, 1)).astype(np.int64), end_of_stream=True)
    drive.advance(400)
    cmd, enc = drive.position_counts()
    assert cmd.tolist() == counts([-144.5, 144.5]) and enc.tolist() == cmd.tolist()
    assert np.array_equal(drive.feedback().seq, np.arange(100))


def test_sim_options_are_checked() -> None:
    with pytest.raises(DriveError, match="home_switch_mm' must be a list of 2"):
        SimCard(CONFIG, home_switch_mm=[1.0])
    with pytest.raises(DriveError, match="index_pitch_mm' must be a positive"):
        SimCard(CONFIG, index_pitch_mm=0)
    with pytest.raises(DriveError, match="homed_at_start says the counters are true"):
        SimCard(CONFIG, homed_at_start=True, true_start_mm=[1.0, 0.0])
    with pytest.raises(DriveError, match="unknown drive option 'home_mm'"):
        SimCard(CONFIG, home_mm=[0.0, 0.0])


def test_trapezoid_moves_sum_exactly_and_respect_speed() -> None:
    steps = trapezoid_counts(-4000, 20_000.0, 500_000.0, 0.001)
    assert steps.sum() == -4000 and np.abs(steps).max() <= 21
    frames = move_frames(np.array([0, 5]), np.array([7, 5]), np.array([20.0, 20.0]),
                         np.array([500.0, 500.0]), np.array([0.001, 0.001]), 0.001)
    assert frames.sum(axis=0).tolist() == [7, 0]
