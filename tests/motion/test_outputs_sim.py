"""Machine outputs on the sim card through the whole runtime (interpreter and generator in their
own processes, virtual time): set in program order when the machine stands at them, the
spindle's spin-up waited before the next move, and the safe state after an abort, an e-stop, a
fault or a limit switch."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from controller.config import MachineConfig, load_config
from controller.motion.types import Outcome
from controller.runtime.processes import Runtime, RuntimeOptions
from drivers.sim.card import SimCard

REPO = Path(__file__).resolve().parents[2]
PROGRAM = """G21 G90
M3 S1000
M8
G1 X10 F600
M62 P0
M64 P1
G1 X20
M68 E0 Q2.5
G1 X30
M5 M9
M2
"""
# xyz_mill's io map: spindle on bit 0, reverse bit 1, speed channel 0; mist 2, flood 3;
# P0 -> bit 4, P1 -> bit 5; E0 -> channel 1.
BIT = {"spindle": 0, "reverse": 1, "mist": 2, "flood": 3, "p0": 4, "p1": 5}


def mill(tmp_path: Path, **io_changes: Any) -> MachineConfig:
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["io"]["spindle"].update(io_changes)
    path = tmp_path / "mill.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(str(path))


def run(tmp_path: Path, config: MachineConfig, text: str = PROGRAM,
        when: Any = None) -> tuple[Any, SimCard, list[dict[str, Any]]]:
    """Run text; when(event, runtime, card) is called on each output event."""
    prog = tmp_path / "prog.nc"
    prog.write_text(text)
    card = SimCard(config, realtime=False)
    events: list[dict[str, Any]] = []
    runtime: Runtime | None = None

    def on_event(event: dict[str, Any]) -> None:
        events.append(event)
        if when is not None:
            when(event, runtime, card)
    runtime = Runtime(str(prog), config, RuntimeOptions(virtual_time=True, drive=card,
                                                        on_event=on_event, rt_priority=None))
    return runtime.run(), card, events


def changes(events: list[dict[str, Any]]) -> list[tuple[int, str, Any]]:
    return [(e["line"], e["name"], e["value"]) for e in events]


def test_outputs_change_in_program_order_at_their_lines(tmp_path: Path) -> None:
    result, card, events = run(tmp_path, mill(tmp_path, spin_up_s=0.0))
    assert result.outcome is Outcome.DONE, result.message
    assert changes(events) == [
        (2, "spindle_rpm", 1000.0), (2, "spindle", "cw"), (3, "coolant_flood", True),
        (5, "digital_0", True), (6, "digital_1", True), (8, "analog_0", 2.5),
        (10, "spindle", "off"), (10, "coolant_flood", False)]
    assert all(e["event"] == "output" for e in events)
    times = [e["t_s"] for e in events]
    assert times == sorted(times)
    # Each output is set at rest where its line stands: after the move before it (10 mm at
    # 10 mm/s takes over a second), never before.
    t_p0 = next(e["t_s"] for e in events if e["name"] == "digital_0")
    assert t_p0 > 1.0
    # The card holds what the program left: P0, P1 on, E0 2.5; spindle and coolant off.
    image = card.output_image
    assert image.bits == (1 << BIT["p0"]) | (1 << BIT["p1"])
    assert image.analog[1] == 2.5 and image.analog[0] == 0.0
    assert result.extra["outputs"]["digital"] == [True, True]
    assert result.final_position_mm["x"] == pytest.approx(30.0, abs=0.002)


def test_a_spindle_start_waits_the_spin_up_before_the_next_move(tmp_path: Path) -> None:
    _, _, quick = run(tmp_path, mill(tmp_path, spin_up_s=0.0))
    result, _, slow = run(tmp_path, mill(tmp_path, spin_up_s=0.75))
    assert result.outcome is Outcome.DONE, result.message
    t_quick = {(e["line"], e["name"]): e["t_s"] for e in quick}
    t_slow = {(e["line"], e["name"]): e["t_s"] for e in slow}
    # The spindle starts at the same time; everything after it comes 0.75 s later (the wait
    # is planned samples at rest, so it is exact to a sample of a few at most).
    assert t_slow[(2, "spindle")] == pytest.approx(t_quick[(2, "spindle")], abs=0.005)
    for key in ((3, "coolant_flood"), (5, "digital_0"), (10, "spindle")):
        assert t_slow[key] - t_quick[key] == pytest.approx(0.75, abs=0.005), key


def test_spindle_speed_output_follows_s_while_on(tmp_path: Path) -> None:
    seen: dict[int, tuple[int, float]] = {}  # line -> the card's outputs once it was set

    def when(event: dict[str, Any], runtime: Any, card: SimCard) -> None:
        seen[event["line"]] = (card.output_image.bits, card.output_image.analog[0])
    run(tmp_path, mill(tmp_path), "M4 S500\nS800\nM5\nM2\n", when)
    on_ccw = (1 << BIT["spindle"]) | (1 << BIT["reverse"])
    assert seen == {1: (on_ccw, 500.0), 2: (on_ccw, 800.0), 3: (0, 0.0)}


@pytest.mark.parametrize("stop", ["abort", "estop", "fault", "limit"])
def test_every_stop_sets_the_safe_state(tmp_path: Path, stop: str) -> None:
    def when(event: dict[str, Any], runtime: Any, card: SimCard) -> None:
        if event["name"] != "digital_1" or event.get("safe"):
            return
        if stop == "abort":
            runtime.request_abort("aborted by test")
        elif stop == "estop":
            runtime.controller.request_estop("e-stop by test")
        elif stop == "fault":
            card.inject_drive_fault(0)
        else:
            card.trip_limit_input(0, 1)
    result, card, events = run(tmp_path, mill(tmp_path), when=when)
    assert result.outcome is (Outcome.ABORTED if stop in ("abort", "estop") else Outcome.FAULT)
    if stop == "limit":
        assert result.message == "hard limit: X+ limit switch tripped"
    assert card.output_image.bits == 0 and card.output_image.analog == (0.0,) * 4
    assert result.extra["outputs"] == {"spindle": "off", "spindle_rpm": 1000.0,
                                       "coolant_mist": False, "coolant_flood": False,
                                       "digital": [False, False], "analog": [0.0]}
    safe = [(e["name"], e["value"]) for e in events if e.get("safe")]
    assert safe == [("spindle", "off"), ("coolant_flood", False), ("digital_0", False),
                    ("digital_1", False)]
    # Category 1 for the e-stop and the limit switch: the drives end disabled.
    assert card.disabled is (stop in ("estop", "limit"))


def test_configured_safe_values_are_what_a_stop_leaves(tmp_path: Path) -> None:
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["io"]["digital"][1]["safe"] = True  # say, a brake released only when powered
    data["io"]["analog"][0]["safe"] = 1.5
    path = tmp_path / "safe.yaml"
    path.write_text(yaml.safe_dump(data))

    def when(event: dict[str, Any], runtime: Any, card: SimCard) -> None:
        if event["name"] == "digital_0" and not event.get("safe"):
            runtime.request_abort("aborted by test")
    result, card, _ = run(tmp_path, load_config(str(path)), when=when)
    assert result.outcome is Outcome.ABORTED
    assert card.output_image.bits == 1 << BIT["p1"]
    assert card.output_image.analog[1] == 1.5


@pytest.mark.parametrize("hold_at_s", [0.9, 0.98, 1.0, 1.02, 1.04, 1.06, 1.1, 1.2])
def test_a_feed_hold_at_an_output_mark_sets_it_once_and_resumes(tmp_path: Path,
                                                                hold_at_s: float) -> None:
    """Hold asked as the machine nears, reaches or leaves the M62's place (the move to X10
    takes about 1.05 s; M62 P0 goes with the first frame of line 4, frames a hold may take
    back and send again) and the M64's mark: each output is set once, in its place, and the
    job goes on after resume."""
    config = mill(tmp_path, spin_up_s=0.0)
    prog = tmp_path / "prog.nc"
    prog.write_text("G21 G90\nG1 X10 F600\nM62 P0\nG1 X20\nM64 P1\nM2\n")
    events: list[dict[str, Any]] = []
    asked: list[str] = []
    runtime: Runtime | None = None

    def progress(p: Any) -> None:
        if not asked and p.executed_s >= hold_at_s:
            asked.append("hold")
            runtime.request_hold()  # type: ignore[union-attr]
        elif asked == ["hold"] and p.state.value == "held":
            asked.append("resume")
            runtime.request_resume()  # type: ignore[union-attr]
    card = SimCard(config, realtime=False)
    runtime = Runtime(str(prog), config, RuntimeOptions(
        virtual_time=True, drive=card, on_event=events.append, on_progress=progress,
        rt_priority=None, settings={"progress_every_s": 0.002}))
    result = runtime.run()
    assert result.outcome is Outcome.DONE, result.message
    assert asked == ["hold", "resume"]
    assert changes(events) == [(4, "digital_0", True), (5, "digital_1", True)]
    assert card.output_image.bits == (1 << BIT["p0"]) | (1 << BIT["p1"])
    ((seq, _),) = card.frame_outputs.clocked  # the card set P0 once, at one frame
    assert result.final_position_mm["x"] == pytest.approx(20.0, abs=0.002)


@pytest.mark.parametrize("target_x, stops", [(-5.0, False), (5.0, True)])
def test_a_job_may_move_off_a_limit_switch_but_not_further_onto_it(
        tmp_path: Path, target_x: float, stops: bool) -> None:
    """After a limit stop the axis stands on its switch: a jog or program that moves it away
    runs; one that goes further toward it stops at once."""
    config = mill(tmp_path)
    prog = tmp_path / "prog.nc"
    prog.write_text(f"G21 G90\nG1 X{target_x} F600\nM2\n")
    card = SimCard(config, realtime=False)
    card.trip_limit_input(0, 1)  # X+ is open before the job starts
    result = Runtime(str(prog), config, RuntimeOptions(virtual_time=True, drive=card,
                                                       rt_priority=None)).run()
    if stops:  # seen in the first rows read, before any frame went out: nothing moved
        assert result.outcome is Outcome.FAULT
        assert result.message == ("hard limit: X+ limit switch tripped; the job would move X "
                                  "further onto it")
        assert result.final_position_mm["x"] == 0.0
    else:
        assert result.outcome is Outcome.DONE, result.message
        assert result.final_position_mm["x"] == pytest.approx(-5.0, abs=0.002)


def test_another_switch_opening_while_on_one_stops_the_job(tmp_path: Path) -> None:
    def when(event: dict[str, Any], runtime: Any, card: SimCard) -> None:
        if event["name"] == "digital_1":
            card.trip_limit_input(1, -1)  # Y- opens while X+ has been open all along
    config = mill(tmp_path)
    prog = tmp_path / "prog.nc"
    prog.write_text("G21 G90\nM62 P1\nG1 X-20 F600\nM2\n")
    card = SimCard(config, realtime=False)
    card.trip_limit_input(0, 1)
    events: list[dict[str, Any]] = []
    runtime = Runtime(str(prog), config, RuntimeOptions(
        virtual_time=True, drive=card, rt_priority=None,
        on_event=lambda e: (events.append(e), when(e, runtime, card))))
    result = runtime.run()
    assert result.outcome is Outcome.FAULT
    assert result.message == "hard limit: Y- limit switch tripped"
    assert result.final_position_mm["x"] > -1.0  # stopped long before X-20
