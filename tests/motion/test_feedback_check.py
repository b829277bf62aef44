"""Feedback no drive could have given is caught: an encoder jump, a position off the travel."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import load_config
from controller.motion.feedback_check import FeedbackCheck
from drivers.base import Feedback

CONFIG = load_config("xy_table")


def _fb(rows: list[list[int]], seq0: int = 0) -> Feedback:
    enc = np.array(rows, dtype=np.int64)
    return Feedback(np.arange(seq0, seq0 + len(rows)), enc.copy(), enc)


def test_a_bit_flip_on_the_link_is_implausible() -> None:
    """8388.608 mm in one period: what a flipped bit 23 read on the slcan link."""
    check = FeedbackCheck(CONFIG, np.array([1000, 2000]))
    assert check.check(_fb([[1058, 2000], [1116, 2000]])) is None  # 58 mm/s: fine
    trip = check.check(_fb([[1116, 2000 + (1 << 23)]], seq0=2))
    assert trip is not None and trip.axis == "y" and trip.seq == 2
    assert "jumped 8388.608 mm in 1 period(s)" in trip.message and "unknown" in trip.message


def test_a_position_off_the_travel_is_implausible() -> None:
    check = FeedbackCheck(CONFIG, np.array([149_900, 0]))
    trip = check.check(_fb([[149_950, 0], [150_000, 0], [150_050, 0]] + [
        [150_050 + 50 * i, 0] for i in range(1, 200)]))
    assert trip is not None and trip.axis == "x" and "off its travel" in trip.message


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=300))
def test_any_motion_within_the_axis_limits_passes(accels: list[float]) -> None:
    """Every sequence of steps an axis can make (up to its max velocity, with the servo's
    overshoot) inside the travel passes."""
    vmax = CONFIG.axes[0].max_velocity_mm_s
    step_max = vmax * CONFIG.sample_period_s / CONFIG.axes[0].pulse_mm  # counts per period
    steps = np.clip(np.cumsum(accels), -1.0, 1.0) * step_max * 1.5
    x = np.rint(np.cumsum(steps)).astype(np.int64)
    check = FeedbackCheck(CONFIG, np.array([0, 0]))
    assert check.check(_fb([[int(v), 0] for v in x])) is None


@pytest.mark.parametrize("name", ["canopen", "serial", "xyz_mill"])
def test_every_shipped_machine_builds_its_check(name: str) -> None:
    config = load_config(name)
    check = FeedbackCheck(config, np.zeros(len(config.axes), dtype=np.int64))
    assert check.check(_fb([[0] * len(config.axes)])) is None


def test_readings_frames_apart_are_allowed_the_motion_of_those_frames() -> None:
    """The serial card reports every few frames: 0.4 mm between readings 10 frames apart is
    58 mm/s, not a jump (a per-row limit faulted the airfoil on the serial card)."""
    check = FeedbackCheck(CONFIG, np.array([0, 0]))
    enc = np.array([[400, 0], [800, 0]], dtype=np.int64)
    assert check.check(Feedback(np.array([9, 19]), enc.copy(), enc)) is None
    enc = np.array([[1200, 0]], dtype=np.int64)
    assert check.check(Feedback(np.array([20]), enc.copy(), enc)) is not None


def test_a_halted_cards_motors_may_close_their_following_error_in_one_row() -> None:
    """A card halted mid-motion (a bad frame) stops its frame counter, but its motors still
    close their following error: the serial card's next report moved 0.241 mm one frame on.
    That is believed while the card is halted (settling); a bit flip is not."""
    ferror_counts = max(CONFIG.axes[0].ferror_mm, CONFIG.axes[0].min_ferror_mm) / 0.001
    check = FeedbackCheck(CONFIG, np.array([1000, 2000]))
    settle = int(check.max_step_counts[0] + 0.5 * ferror_counts)
    assert check.check(_fb([[1000 + settle, 2000]])) is not None  # running: a jump
    check = FeedbackCheck(CONFIG, np.array([1000, 2000]))
    assert check.check(_fb([[1000 + settle, 2000]]), settling=True) is None
    flip = check.believed(_fb([[1000 + settle, 2000 + (1 << 23)]], seq0=1), settling=True)
    assert flip[1] is not None and flip[1].axis == "y" and len(flip[0]) == 0


@pytest.mark.parametrize("rows", [1, 2, 3])  # a cycle's rows (a frame each), and a block's
def test_a_jump_in_the_second_row_of_a_cycle_is_named_at_its_frame(rows: int) -> None:
    check = FeedbackCheck(CONFIG, np.array([1000, 2000]))
    assert check.check(_fb([[1058, 2000]])) is None  # frame 0
    moves = [[1058 + 58 * k, 2000] for k in range(1, rows + 1)]
    moves[min(1, rows - 1)][1] += 5000  # 5 mm in a period
    trip = check.check(_fb(moves, seq0=1))
    assert trip is not None and trip.axis == "y" and trip.seq == 1 + min(1, rows - 1)
    assert "jumped 5.000 mm in 1 period(s) (at most" in trip.message
