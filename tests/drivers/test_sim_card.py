"""The simulated bit-pattern card: FIFO clocking, servo model, latched flags, fault hooks."""

from __future__ import annotations

import time

import numpy as np
import pytest
from runtime_helpers import virtual_card, xy_config

from controller.servo.model import discretise
from drivers.base import CardStatus
from drivers.errors import (
    BadFrameError,
    DriveError,
    DriveFaultError,
    LostCommunicationError,
    UnderrunError,
)
from drivers.registry import make_drive


def ramp_frames(n: int, per_frame: int = 58) -> np.ndarray:
    return np.tile([per_frame, -per_frame], (n, 1)).astype(np.int64)


def test_registry_builds_the_configured_backend() -> None:
    drive = make_drive(xy_config(), realtime=False)
    assert type(drive).__name__ == "SimCard" and drive.fifo_capacity() == 256


def test_frames_execute_and_encoder_settles_exactly() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(200), end_of_stream=True)
    assert card.fifo_level() == 200
    card.advance(150)
    assert card.fifo_level() == 50
    card.advance(300)  # the rest, then 250 idle periods to settle
    cmd, enc = card.position_counts()
    assert np.array_equal(cmd, [200 * 58, -200 * 58]) and np.array_equal(enc, cmd)
    fb = card.feedback()
    assert np.array_equal(fb.seq, np.arange(200)) and card.status() == CardStatus.OK


def test_steady_following_error_is_the_servo_model_value() -> None:
    """58 pulses/ms = 58 mm/s: e_ss = V (a1 - b1) / a0 (docs/algorithms.md, The servo model
    (eq. 27): 18.56 um at 58 mm/s)."""
    cfg = xy_config()
    card = virtual_card(cfg)
    card.write_frames(ramp_frames(250), end_of_stream=True)
    card.advance(240)
    fb = card.feedback()
    lag_um = (fb.commanded_counts[-1, 0] - fb.encoder_counts[-1, 0]) * 1.0
    expected_um = 58.0 * discretise(cfg.axes[0].servo, cfg.sample_period_s).steady_lag_s * 1e3
    assert abs(lag_um - expected_um) <= 1.0  # encoder quantised to 1 um


def test_underrun_latches_mid_program_and_stops_until_reset() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(20))  # no end-of-stream: the program continues
    card.advance(30)
    assert CardStatus.UNDERRUN in card.status()
    assert "underrun" in card.fault_message()
    with pytest.raises(UnderrunError):
        card.write_frames(ramp_frames(5))
    card.reset()
    assert card.status() == CardStatus.OK
    card.write_frames(ramp_frames(5), end_of_stream=True)
    card.advance(10)
    assert card.status() == CardStatus.OK and card.position_counts()[0][0] == 25 * 58


def test_empty_fifo_after_end_of_stream_is_idle_not_underrun() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(20))
    card.write_frames(np.zeros((0, 2), dtype=np.int64), end_of_stream=True)
    card.advance(100)
    assert card.status() == CardStatus.OK


def test_bad_frame_and_overflow_are_refused() -> None:
    card = virtual_card(xy_config(), fifo_frames=16)
    with pytest.raises(BadFrameError):
        card.write_frames(np.array([[128, 0]]))
    card.reset()
    with pytest.raises(BadFrameError, match="overflow"):
        card.write_frames(ramp_frames(17))


def test_injected_drive_fault_names_the_axis_and_halts() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(100), end_of_stream=True)
    card.advance(30)
    card.inject_drive_fault(1, 0x2310)
    card.advance(30)
    assert CardStatus.FAULT in card.status()
    assert card.fault_message() == "Y axis drive fault 0x2310"
    assert card.fifo_level() == 70  # nothing clocked after the fault
    with pytest.raises(DriveFaultError):
        card.write_frames(ramp_frames(1))


def test_stall_and_lag_move_the_encoder_only() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(200), end_of_stream=True)
    card.advance(50)
    card.inject_stall(0)
    card.inject_lag(1, 0.5, ramp_frames=10)
    card.advance(400)
    cmd, enc = card.position_counts()
    assert np.array_equal(cmd, [200 * 58, -200 * 58])
    assert cmd[0] - enc[0] > 5000  # x stopped near 50 frames in
    assert abs(abs(enc[1] - cmd[1]) - 500) <= 1  # y off by the injected 0.5 mm (500 pulses)


def test_lost_comm_raises_and_the_card_underruns_on_its_own() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(20))
    card.inject_lost_comm()
    with pytest.raises(LostCommunicationError):
        card.fifo_level()
    card.advance(40)
    card.restore_comm()
    assert CardStatus.UNDERRUN in card.status()
    assert card.position_counts()[0][0] == 20 * 58


def test_injected_underrun_accounts_the_dropped_pulses() -> None:
    card = virtual_card(xy_config())
    card.write_frames(ramp_frames(50))
    card.advance(10)
    card.inject_underrun()
    card.advance(1)
    assert CardStatus.UNDERRUN in card.status()
    executed = card.position_counts()[0]
    assert np.array_equal(executed + card.discarded_counts, [50 * 58, -50 * 58])


def test_realtime_mode_clocks_on_the_wall_clock() -> None:
    card = make_drive(xy_config(), realtime=True)
    card.open()
    try:
        card.write_frames(ramp_frames(200), end_of_stream=True)
        time.sleep(0.1)
        level = card.fifo_level()
    finally:
        card.close()
    assert 80 <= 200 - level <= 140  # ~100 frames in 100 ms (loose: a shared CI machine)


def test_an_unknown_drive_option_is_an_error_naming_it() -> None:
    config = xy_config().with_drive_options({"fifo_frame": 64})
    with pytest.raises(DriveError, match="unknown drive option 'fifo_frame'"):
        make_drive(config, realtime=False)


@pytest.mark.parametrize("pole_pct,gain_pct", [(0.0, 0.0), (-20.0, 0.0), (0.0, 20.0)])
def test_the_card_can_run_a_plant_off_the_model(pole_pct: float, gain_pct: float) -> None:
    """Steady lag at 58 pulses/ms: V (a1 - b1) / a0 of the mismatched plant, not the model."""
    from controller.servo.model import mismatched

    card = virtual_card(xy_config(), plant_pole_pct=pole_pct, plant_gain_pct=gain_pct)
    card.write_frames(ramp_frames(250), end_of_stream=True)
    card.advance(240)
    fb = card.feedback()
    lag_mm = (fb.commanded_counts[-1, 0] - fb.encoder_counts[-1, 0]) * 0.001
    p = mismatched(xy_config().axis("x").servo, pole_pct, gain_pct)
    assert lag_mm == pytest.approx(58.0 * (p.a1 - p.b1) / p.a0, abs=0.0011)


@pytest.mark.parametrize("key, value", [("plant_pole_pct", 1e300), ("plant_gain_pct", "x"),
                                        ("fifo_frames", 0), ("max_pulses_per_frame", -1)])
def test_a_drive_option_out_of_range_names_itself(key: str, value: object) -> None:
    """plant_pole_pct 1e300 was an OverflowError deep in the servo model."""
    from controller.config import load_config
    from drivers.errors import DriveError
    from drivers.sim.card import SimCard

    with pytest.raises(DriveError, match=f"sim: drive option {key}: "):
        SimCard(load_config("xy_table"), realtime=False, **{key: value})
