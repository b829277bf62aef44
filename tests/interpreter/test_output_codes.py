"""M3-M5 with S, M7-M9, M62-M65, M67, M68: one OutputBlock per line, checked against the config's
`io` map before any motion; and the `io` section read strictly."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from controller.blocks import LineBlock, OutputBlock, StopBlock
from controller.config import load_config
from controller.errors import ConfigError, NcError
from controller.interpreter.program import read_program

REPO = Path(__file__).resolve().parents[2]
MILL = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())  # spin_up_s 1.0


def config(tmp_path: Path, io: Any = None) -> Any:
    data = dict(MILL)
    if io is not None:
        data["io"] = io
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(str(path))


def blocks(tmp_path: Path, text: str, io: Any = None, **kw: Any) -> list[Any]:
    prog = tmp_path / "p.nc"
    prog.write_text(text)
    return list(read_program(str(prog), config(tmp_path, io), **kw))


def outputs(b: list[Any]) -> list[tuple[int, list[tuple[str, Any]], float]]:
    return [(x.source.first_line, [(c.name, c.value) for c in x.changes], x.wait_s)
            for x in b if isinstance(x, OutputBlock)]


def test_digital_and_analog_outputs(tmp_path: Path) -> None:
    b = blocks(tmp_path, "M62 P0\nM63 P0\nM64 P1\nM65 P1\nM67 E0 Q2.5\nM68 E0 Q0\n")
    assert outputs(b) == [(1, [("digital_0", True)], 0.0), (2, [("digital_0", False)], 0.0),
                          (3, [("digital_1", True)], 0.0), (4, [("digital_1", False)], 0.0),
                          (5, [("analog_0", 2.5)], 0.0), (6, [("analog_0", 0.0)], 0.0)]


def test_outputs_come_before_the_move_of_their_line(tmp_path: Path) -> None:
    b = blocks(tmp_path, "G1 X1 F600 M62 P0\n")
    assert isinstance(b[0], OutputBlock) and isinstance(b[1], LineBlock)
    assert b[0].position == (0.0, 0.0, 0.0)


def test_the_spindle_waits_its_spin_up_on_start_reversal_and_speed_change(tmp_path: Path) -> None:
    b = blocks(tmp_path, "S1000\nM3\nS1000\nS2000\nM4\nM8\nM5\nS500\nM3\n")
    assert outputs(b) == [
        (1, [("spindle_rpm", 1000.0)], 0.0),  # set while off: nothing to wait for
        (2, [("spindle", "cw")], 1.0),
        (4, [("spindle_rpm", 2000.0)], 1.0),  # line 3 changed nothing: no block
        (5, [("spindle", "ccw")], 1.0),
        (6, [("coolant_flood", True)], 0.0),
        (7, [("spindle", "off")], 0.0),
        (8, [("spindle_rpm", 500.0)], 0.0),
        (9, [("spindle", "cw")], 1.0)]


def test_program_end_stops_spindle_and_coolant_only_when_on(tmp_path: Path) -> None:
    assert outputs(blocks(tmp_path, "G1 X1 F600\nM2\n")) == []
    b = blocks(tmp_path, "M3 S100\nM7\nM62 P0\nM30\n")
    assert outputs(b)[-1] == (4, [("spindle", "off"), ("coolant_mist", False),
                                  ("coolant_flood", False)], 0.0)
    assert isinstance(b[-1], StopBlock)


def test_run_from_line_sets_again_what_the_lines_before_set(tmp_path: Path) -> None:
    b = blocks(tmp_path, "M3 S1000\nM8\nG1 X10 F600\nM62 P0\nG1 X20\nG1 X30\n", from_line=6)
    assert outputs(b) == [(6, [("spindle_rpm", 1000.0), ("spindle", "cw"),
                               ("coolant_flood", True), ("digital_0", True)], 1.0)]
    assert b[0].position == (20.0, 0.0, 0.0)


@pytest.mark.parametrize("text, message", [
    ("M62\n", "1:1: error: M62 needs P (the output number)"),
    ("M62 P2\n", "1:5: error: M62 P2: no digital output 2 in the config's io.digital "
                 "(mapped: P0-P1)"),
    ("M64 P0.5\n", "1:5: error: M64 P must be a non-negative integer"),
    ("M67 E1 Q1\n", "1:5: error: M67 E1: no analog output 1 in the config's io.analog "
                    "(mapped: E0-E0)"),
    ("M68 E0\n", "1:1: error: M68 needs Q (the value)"),
    ("M68 E0 Q12\n", "1:8: error: M68 E0 Q12 is outside [0, 10] (io.analog[0])"),
    ("G0 X1 E2\n", "1:7: error: E word with no M67 or M68 on the line (nor exponents: write "
                   "1e3 as 1000)"),
    ("M62 P0 M63\n", "1:8: error: M63 and M62 are both in the digital output modal group"),
])
def test_bad_output_words_name_file_line_and_word(tmp_path: Path, text: str,
                                                  message: str) -> None:
    with pytest.raises(NcError) as info:
        blocks(tmp_path, text)
    assert info.value.format() == f"{tmp_path / 'p.nc'}:{message}"


def test_without_an_io_map_the_outputs_are_state_only_and_m62_is_refused(tmp_path: Path) -> None:
    b = blocks(tmp_path, "M3 S100\n", io={})
    assert outputs(b) == [(1, [("spindle_rpm", 100.0), ("spindle", "cw")], 0.0)]
    with pytest.raises(NcError, match=r"no digital output 0 .* \(mapped: none\)"):
        blocks(tmp_path, "M62 P0\n", io={})


@pytest.mark.parametrize("io, key, why", [
    ({"spindle": {"spin_up": 1.0}}, "io.spindle.spin_up", "unknown key"),
    ({"spindle": {"on_bit": 16}}, "io.spindle.on_bit", "must be in [0, 15]"),
    ({"spindle": {"on_bit": 3}, "coolant": {"flood_bit": 3}}, "io.coolant.flood_bit",
     "3 is already io.spindle.on_bit"),
    ({"digital": [{"bit": 2}, {"bit": 2}]}, "io.digital[1].bit", "2 is already io.digital[0].bit"),
    ({"digital": [{"bit": 2, "save": True}]}, "io.digital[0].save", "unknown key"),
    ({"analog": [{"channel": 0, "safe": 11.0}]}, "io.analog[0].safe", "must be <= 10.0"),
    ({"analog": [{"channel": 4}]}, "io.analog[0].channel", "must be in [0, 3]"),
    ({"spindle": {"speed_channel": 1}, "analog": [{"channel": 1}]}, "io.analog[0].channel",
     "1 is already io.spindle.speed_channel"),
    ({"digital": {"bit": 1}}, "io.digital", "must be a list"),
    ({"spindle": {"spin_up_s": 90}}, "io.spindle.spin_up_s", "must be <= 60.0"),
])
def test_the_io_section_is_strict(tmp_path: Path, io: Any, key: str, why: str) -> None:
    with pytest.raises(ConfigError) as info:
        config(tmp_path, io)
    assert key in str(info.value) and why in str(info.value)
