"""The spindle's at-speed input on the sim card (io.spindle.at_speed_input): the machine stands
at a spindle start until the input is true, and a spindle that never gets there ends the job in
FAULT with the outputs safe."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from controller.config import MachineConfig, load_config
from controller.errors import ConfigError
from controller.motion.types import Outcome
from controller.runtime.processes import Runtime, RuntimeOptions
from drivers.errors import DriveError
from drivers.sim.card import SimCard

REPO = Path(__file__).resolve().parents[2]
PROGRAM = "G21 G90\nM3 S1000\nM8\nG1 X10 F600\nS2000\nG1 X20\nM5 M9\nM2\n"


def mill(tmp_path: Path, **spindle: Any) -> Path:
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["io"]["spindle"].update(spindle)
    path = tmp_path / "mill.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def at_speed_mill(tmp_path: Path, timeout_s: float = 5.0) -> MachineConfig:
    return load_config(
        str(mill(tmp_path, spin_up_s=0.0, at_speed_input=True, at_speed_timeout_s=timeout_s))
    )


def run(
    tmp_path: Path, config: MachineConfig, card: SimCard, text: str = PROGRAM
) -> tuple[Any, dict[tuple[int, str], float]]:
    prog = tmp_path / "prog.nc"
    prog.write_text(text)
    seen: dict[tuple[int, str], float] = {}  # (line, output) -> the card's clock when set

    def on_event(event: dict[str, Any]) -> None:
        if not event.get("safe"):  # (an event's t_s counts frames run: not the time at rest)
            seen[(event["line"], event["name"])] = card.frames_clocked * config.sample_period_s

    result = Runtime(
        str(prog),
        config,
        RuntimeOptions(virtual_time=True, drive=card, on_event=on_event, rt_priority=None),
    ).run()
    return result, seen


def test_a_spindle_start_stands_until_the_input_then_goes_on(tmp_path: Path) -> None:
    config = at_speed_mill(tmp_path)
    _, quick = run(tmp_path, config, SimCard(config, realtime=False))
    card = SimCard(config, realtime=False, spindle_spinup_s=0.6)
    result, slow = run(tmp_path, config, card)
    assert result.outcome is Outcome.DONE, result.message
    assert slow[(2, "spindle")] == pytest.approx(quick[(2, "spindle")], abs=0.005)
    # Everything after the start waits for the input: 0.6 s of the card's clock, and no more
    # than a few motion cycles (the loop reads the input once a cycle) beyond. The speed
    # change of line 5 (spindle on) waits again: the end comes 2 x 0.6 s later.
    cycles_s = 0.02
    for key, waits in (((3, "coolant_flood"), 1), ((7, "spindle"), 2)):
        late_s = slow[key] - quick[key]
        assert waits * 0.6 - 0.005 <= late_s <= waits * 0.6 + waits * cycles_s, key
    assert result.final_position_mm["x"] == pytest.approx(20.0, abs=0.002)


def test_a_spindle_never_at_speed_faults_with_the_outputs_safe(tmp_path: Path) -> None:
    config = at_speed_mill(tmp_path, timeout_s=0.3)
    card = SimCard(config, realtime=False, spindle_spinup_s="never")
    result, seen = run(tmp_path, config, card)
    assert result.outcome is Outcome.FAULT
    assert result.message == (
        "line 2: spindle not at speed within 0.3 s (input: sim card, "
        "option spindle_spinup_s, io.spindle.at_speed_timeout_s)"
    )
    assert (3, "coolant_flood") not in seen  # nothing after the start was done
    assert card.frames_clocked * config.sample_period_s >= 0.3  # it waited the time-out
    assert card.output_image.bits == 0 and card.output_image.analog == (0.0,) * 4
    assert result.extra["outputs"]["spindle"] == "off"
    assert result.position_known
    assert result.final_position_mm["x"] == pytest.approx(0.0, abs=0.002)


def test_a_hold_asked_during_the_wait_holds_there_once_at_speed(tmp_path: Path) -> None:
    config = at_speed_mill(tmp_path)
    card = SimCard(config, realtime=False, spindle_spinup_s=0.4)
    prog = tmp_path / "prog.nc"
    prog.write_text("G21 G90\nM3 S1000\nG1 X5 F600\nM2\n")
    runtime: Runtime | None = None
    states: list[tuple[str, bool]] = []  # (state, input) from the hold on

    def on_event(event: dict[str, Any]) -> None:
        if event["name"] == "spindle" and event["value"] == "cw":
            runtime.request_hold()  # type: ignore[union-attr]  # the wait begins now

    def progress(p: Any) -> None:
        states.append((p.state.value, card.at_speed_input()))
        if p.state.value == "held" and states.count(states[-1]) == 1:
            runtime.request_resume()  # type: ignore[union-attr]

    runtime = Runtime(
        str(prog),
        config,
        RuntimeOptions(
            virtual_time=True,
            drive=card,
            on_event=on_event,
            on_progress=progress,
            rt_priority=None,
            settings={"progress_every_s": 0.01},
        ),
    )
    result = runtime.run()
    assert result.outcome is Outcome.DONE, result.message
    held = [at_speed for state, at_speed in states if state == "held"]
    assert held and all(held)  # held only once the spindle was at speed
    assert result.final_position_mm["x"] == pytest.approx(5.0, abs=0.002)


def test_an_abort_during_the_wait_ends_it_at_once(tmp_path: Path) -> None:
    config = at_speed_mill(tmp_path)
    card = SimCard(config, realtime=False, spindle_spinup_s="never")
    prog = tmp_path / "prog.nc"
    prog.write_text(PROGRAM)
    runtime: Runtime | None = None

    def on_event(event: dict[str, Any]) -> None:
        if event["name"] == "spindle" and event["value"] == "cw":
            runtime.request_abort("aborted by test")  # type: ignore[union-attr]

    runtime = Runtime(
        str(prog),
        config,
        RuntimeOptions(virtual_time=True, drive=card, on_event=on_event, rt_priority=None),
    )
    result = runtime.run()
    assert result.outcome is Outcome.ABORTED and result.message == "aborted by test"
    assert card.frames_clocked * config.sample_period_s < 1.0  # not the 5 s time-out
    assert card.output_image.bits == 0 and result.final_position_mm["x"] == 0.0


def test_without_the_input_configured_the_card_option_changes_nothing(tmp_path: Path) -> None:
    config = load_config(str(mill(tmp_path, spin_up_s=0.0)))
    result, _ = run(tmp_path, config, SimCard(config, realtime=False, spindle_spinup_s="never"))
    assert result.outcome is Outcome.DONE, result.message


@pytest.mark.parametrize(
    "spindle, key, says",
    [
        ({"at_speed_input": True, "spin_up_s": 1.0}, "io.spindle.spin_up_s", "must be 0 with"),
        ({"at_speed_timeout_s": 0.0}, "io.spindle.at_speed_timeout_s", "must be > 0"),
        ({"at_speed_timeout_s": 601}, "io.spindle.at_speed_timeout_s", "must be <= 600"),
        ({"at_speed_input": "yes"}, "io.spindle.at_speed_input", ""),
        ({"at_speed_inpt": True}, "io.spindle.at_speed_inpt", ""),
    ],
)
def test_config_keys_are_strict(
    tmp_path: Path, spindle: dict[str, Any], key: str, says: str
) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(str(mill(tmp_path, **spindle)))
    assert key in str(err.value) and says in str(err.value)


@pytest.mark.parametrize("value", ["soon", "-1", "700"])
def test_the_card_option_is_checked(tmp_path: Path, value: str) -> None:
    config = load_config(str(mill(tmp_path)))
    with pytest.raises(DriveError, match="spindle_spinup_s"):
        SimCard(config, realtime=False, spindle_spinup_s=value)
