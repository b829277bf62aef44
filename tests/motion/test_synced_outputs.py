"""M62/M63/M67 travel with the frames on the sim card (whole runtime, virtual time): the job
does not come to rest at them, and each is set as the card clocks the first sample of the
move after it; M64/M68 still stop there."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller.config import load_config
from controller.generator.plan import generate_reference
from controller.interpreter.program import read_program
from controller.motion.types import Outcome
from controller.runtime.processes import Runtime, RuntimeOptions
from drivers.sim.card import SimCard

MILL = load_config("xyz_mill")  # P0 -> bit 4, E0 -> analog channel 1
SYNCED = "G21 G90 G64 F1200\nG1 X10\nM62 P0\nG1 X20 Y5\nM67 E0 Q4.5\nG1 X30\nM2\n"
PLAIN = "G21 G90 G64 F1200\nG1 X10\nG1 X20 Y5\nG1 X30\nM2\n"


def run(tmp_path: Path, text: str) -> tuple[Any, SimCard, list[dict[str, Any]]]:
    prog = tmp_path / "prog.nc"
    prog.write_text(text)
    card = SimCard(MILL, realtime=False)
    events: list[dict[str, Any]] = []
    result = Runtime(
        str(prog),
        MILL,
        RuntimeOptions(virtual_time=True, drive=card, on_event=events.append, rt_priority=None),
    ).run()
    assert result.outcome is Outcome.DONE, result.message
    return result, card, events


def first_samples(tmp_path: Path, text: str, lines: tuple[int, ...]) -> list[int]:
    """The index of each line's first reference sample, from the generator alone."""
    prog = tmp_path / "ref.nc"
    prog.write_text(text)
    line = np.concatenate([c.line for c in generate_reference(read_program(str(prog), MILL), MILL)])
    return [int(np.flatnonzero(line == n)[0]) for n in lines]


def test_m62_and_m67_go_with_the_next_move_without_a_stop(tmp_path: Path) -> None:
    synced, card, events = run(tmp_path, SYNCED)
    plain, _, _ = run(tmp_path, PLAIN)
    # no rest at them: the same plan and motion as the program without them
    assert synced.planned_time_s == pytest.approx(plain.planned_time_s, abs=1e-9)
    assert synced.motion_time_s == pytest.approx(plain.motion_time_s, abs=MILL.sample_period_s)
    # set by the card as it clocked the first sample of line 4 (M62) and of line 6 (M67)
    want = first_samples(tmp_path, SYNCED, (4, 6))
    assert [seq for seq, _ in card.frame_outputs.clocked] == want
    outputs = [(e["line"], e["name"], e["value"], e["t_s"]) for e in events]
    period_s = MILL.sample_period_s
    assert outputs == [
        (4, "digital_0", True, pytest.approx(want[0] * period_s)),
        (6, "analog_0", 4.5, pytest.approx(want[1] * period_s)),
    ]
    assert card.output_image.bits == 1 << 4 and card.output_image.analog[1] == 4.5


def test_m64_and_m68_still_stop_there(tmp_path: Path) -> None:
    now, card, _ = run(tmp_path, SYNCED.replace("M62", "M64").replace("M67", "M68"))
    plain, _, _ = run(tmp_path, PLAIN)
    # each stops the blend at its line: two rests more than the plain program
    assert now.planned_time_s > plain.planned_time_s + 0.05
    assert card.frame_outputs.clocked == [] and card.output_image.bits == 1 << 4


def test_m62_before_a_dwell_is_set_at_rest_there(tmp_path: Path) -> None:
    """No move follows before another block: set at rest, as an M64 would be."""
    _, card, events = run(tmp_path, "G21 G90\nG1 X5 F600\nM62 P0\nG4 P0.1\nG1 X6\nM2\n")
    assert card.frame_outputs.clocked == []
    assert [(e["line"], e["name"], e["value"]) for e in events] == [(3, "digital_0", True)]
