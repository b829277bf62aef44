"""Blocks of very different feeds: each keeps its own feed, up to a stop or a step of the feed."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import XY_TABLE, blocks_of

from controller.runtime.simulation import report, simulate


@pytest.mark.parametrize(("text", "at_most_s"), [
    # An exact stop (G64 P0 blends nothing) before a line at F1.5: 10 mm at F3500, 1 mm at
    # 0.025 mm/s. The first line crept at F1.5 (440 s): its last feed-limit sample, on the
    # stop, carried the next block's feed, and braking to rest under it was planned as a creep.
    ("G21 G90 G64 P0\nG1 X10 Y0 F3500\nG1 X10 Y1 F1.5\nM2\n", 40.0 + 0.5),
    # A reversal (never blended) before 0.1 mm at F1: 606 s, and 1.2 GB at 50 mm.
    ("G21 G90 G64\nG1 X10 Y0 F3500\nG1 X9.9 Y0 F1\nM2\n", 6.0 + 0.5),
    ("G21 G90 G64\nG1 X50 Y0 F3500\nG1 X49.9 Y0 F1\nM2\n", 6.0 + 1.2),
])
def test_the_block_before_a_stop_keeps_its_feed(tmp_path: Path, text: str,
                                               at_most_s: float) -> None:
    rep = report(simulate(blocks_of(tmp_path, text), XY_TABLE, "ph-lookahead"), "p",
                 "ph-lookahead", XY_TABLE)
    assert rep["contour_limit_met"]
    assert rep["motion_time_s"] <= at_most_s


def test_a_staircase_of_rising_feeds_is_climbed_step_by_step(tmp_path: Path) -> None:
    """F30 for 1 mm, F800 for 69 mm, then F3300: the F800 stretch rose in one segment from the
    F30 node to the next one, whose single shape could not cruise at F800 and rise again, so
    it waited at 0.5 mm/s: 70 mm took 139 s. Each step up is a
    planning node now: about the 7.4 s at the programmed feeds."""
    text = "F30\nG1 Y1\nF800\nG1 Y70\nF3300\nG1 X-2 Y75\nG1 X0 Y79\nM2\n"
    rep = report(simulate(blocks_of(tmp_path, text), XY_TABLE, "ph-lookahead"), "p",
                 "ph-lookahead", XY_TABLE)
    assert rep["contour_limit_met"]
    assert rep["motion_time_s"] < 7.354 * 1.05
