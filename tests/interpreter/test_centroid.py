"""Centroid's codes as the config chooses (gcode.m25, gcode.main_program_m99) and G49 H0."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from nc_helpers import LINUXCNC_START, REPO, mill_with_gcode

from controller.blocks import LineBlock, NcBlock, StopBlock, StopKind
from controller.config import MachineConfig, load_config
from controller.errors import ConfigError, NcError
from controller.interpreter.program import read_program
from controller.interpreter.subprograms import MAX_PROGRAM_PASSES
from controller.offsets import ProgramOffsets

CENTROID = {"m25": "z_home", "main_program_m99": "end"}
# FreeCAD's Centroid post: its preamble, a profile, and its postamble (M25, G49 H0, M99)
CENTROID_POST = (
    "G90 G80 G40 G49\n;begin preamble\nG53 G00 G17\nG21\nG54\nM6 T1\nM3 S1000\n"
    "G0 Z9.0000\nG0 X0.0000 Y-2.5000\nG1 Z-1.0000 F340.2\n"
    "G2 X-2.5000 Y0.0000 I0.0000 J2.5000 F140.4\nG1 X-2.5000 Y3.0000\nG0 Z9.0000\n"
    ";begin postamble\nM5\nM25\nG49 H0\nG90 G80 G40 G49\nM99\n"
)


def read(path: Path, config: MachineConfig) -> tuple[list[NcBlock], list[str]]:
    track = ProgramOffsets()
    blocks = list(read_program(str(path), config, track=track))
    return blocks, track.warnings


def run(tmp_path: Path, text: str, gcode: object, name: str = "prog.nc") -> tuple[list, list]:
    path = tmp_path / name
    path.write_text(text)
    return read(path, mill_with_gcode(tmp_path, gcode))


def lines(blocks: list[NcBlock]) -> list[tuple[bool, tuple[float, ...]]]:
    return [(b.rapid, tuple(b.end)) for b in blocks if isinstance(b, LineBlock)]


def with_z_homing(tmp_path: Path, final_mm: float) -> MachineConfig:
    """xyz_mill with the Centroid rules and a homing sequence on Z that ends at final_mm."""
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["axes"]["z"]["homing"] = {
        "direction": 1,
        "search_mm_s": 10.0,
        "latch_mm_s": 1.0,
        "home_mm": 99.0,
        "final_mm": final_mm,
    }
    data["allow_unhomed"] = True
    path = tmp_path / "homed.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(str(path))


# ---- M25 ------------------------------------------------------------------------------------
def test_m25_is_refused_by_default_naming_centroid_and_the_key(tmp_path: Path) -> None:
    with pytest.raises(NcError) as info:
        run(tmp_path, "G21\nG0 Z5\nM25\nM2\n", LINUXCNC_START)
    err = info.value
    assert (err.line, err.col, err.word) == (3, 1, "M25")
    assert "Centroid: move Z to its home position" in err.message
    assert "gcode.m25: z_home reads it as Centroid does" in err.message


def test_m25_rapids_z_alone_to_machine_home_and_keeps_the_modes(tmp_path: Path) -> None:
    """In machine coordinates past a work offset, in G91, the motion mode G1 staying."""
    text = "G21 G90\nG10 L2 P1 Z-20\nG0 X1 Y2 Z5\nG91 G1 F600\nM25\nX1\nM2\n"
    blocks, warnings = run(tmp_path, text, CENTROID)
    assert lines(blocks) == [
        (True, (1.0, 2.0, -15.0)),  # Z5 in G54, whose Z is -20
        (True, (1.0, 2.0, 100.0)),  # M25: the top of Z's travel (no homing on Z)
        (False, (2.0, 2.0, 100.0)),  # X1: still G91, still G1
    ]
    m25 = [b for b in blocks if isinstance(b, LineBlock)][1]
    assert m25.source.first_line == 5
    assert warnings == [
        f"{tmp_path / 'prog.nc'}:5: M25: Centroid's 'move Z to its home position': a rapid of "
        "Z alone to machine Z100 (gcode.m25: z_home; LinuxCNC refuses M25)"
    ]


def test_m25_goes_where_the_homing_sequence_leaves_z_and_warns_once(tmp_path: Path) -> None:
    path = tmp_path / "prog.nc"
    path.write_text("G20 G90\nG0 X1 Z-1\nM25\nG0 Z-2\nM25\nM2\n")
    blocks, warnings = read(path, with_z_homing(tmp_path, 95.0))
    assert [end for _, end in lines(blocks)] == [
        (25.4, 0.0, -25.4),
        (25.4, 0.0, 95.0),
        (25.4, 0.0, -50.8),
        (25.4, 0.0, 95.0),
    ]
    assert len(warnings) == 1 and "machine Z95 (gcode.m25: z_home" in warnings[0]


@pytest.mark.parametrize("extra", ["M25 M5", "M25 G0", "G53 M25", "M25 Z5"])
def test_m25_stands_alone_on_its_line(tmp_path: Path, extra: str) -> None:
    with pytest.raises(NcError, match="M25 .Centroid's Z home. stands alone") as info:
        run(tmp_path, f"G21\nN20 M25\n{extra}\nM2\n", CENTROID)
    assert info.value.line == 3 and info.value.word == "M25"


def test_m25_on_a_machine_without_z_is_an_error(tmp_path: Path) -> None:
    data = yaml.safe_load((REPO / "config" / "xy_table.yaml").read_text())
    data["gcode"] = {"m25": "z_home"}
    config = tmp_path / "table.yaml"
    config.write_text(yaml.safe_dump(data))
    path = tmp_path / "prog.nc"
    path.write_text("G21\nG0 X1\nM25\nM2\n")
    with pytest.raises(NcError, match="the machine has no Z axis") as info:
        read(path, load_config(str(config)))
    assert info.value.line == 3


# ---- M99 in the main program ----------------------------------------------------------------
def test_m99_in_the_main_program_restarts_by_default(tmp_path: Path) -> None:
    with pytest.raises(NcError, match=f"did not end within {MAX_PROGRAM_PASSES} passes") as info:
        run(tmp_path, "G21 F600\nG1 X10\nG1 X0\nM99\n", LINUXCNC_START)
    assert info.value.line == 4 and info.value.word == "M99"


def test_m99_ending_the_job_is_m2_there_and_reads_no_further(tmp_path: Path) -> None:
    """The same blocks as the program with M2 in its place (spindle off, the end), G54 again."""
    body = "G21 G90 F600\nM3 S1000\nG10 L2 P2 X5\nG55\nG1 X1\n{end}\nG1 X9\n(not read) Q?\n"
    config = mill_with_gcode(tmp_path, CENTROID)
    path = tmp_path / "prog.nc"
    path.write_text(body.format(end="M99"))
    track = ProgramOffsets()
    by_m99 = list(read_program(str(path), config, track=track))
    path.write_text(body.format(end="M2"))
    by_m2 = list(read_program(str(path), config))
    assert by_m99 == by_m2
    assert isinstance(by_m99[-1], StopBlock) and by_m99[-1].kind is StopKind.END
    assert track.table.active == 1  # G54 again, as after M2
    assert track.warnings == [
        f"{path}:6: M99: M99 in the main program ends the job, as M2 "
        "(gcode.main_program_m99: end, Centroid's rule; LinuxCNC's task and Fanuc start the "
        "program again)"
    ]


def test_m99_still_returns_from_a_numbered_program(tmp_path: Path) -> None:
    text = "G21 G90 F600\nM98 P7 L2\nG1 X5\nM99\nO7\nG91 G1 X1\nG90\nM99\n"
    blocks, warnings = run(tmp_path, text, CENTROID)
    assert [end[0] for _, end in lines(blocks)] == [1.0, 2.0, 5.0]
    assert len(warnings) == 1 and ":4: M99: M99 in the main program ends the job" in warnings[0]


# ---- G49 H0 ---------------------------------------------------------------------------------
def test_g49_h0_is_g49_with_a_warning_and_other_h_words_are_refused(tmp_path: Path) -> None:
    blocks, warnings = run(tmp_path, "G21\nG49 H0\nG0 X1\nG49 H0\nM2\n", LINUXCNC_START)
    assert lines(blocks) == [(True, (1.0, 0.0, 0.0))]
    assert warnings == [
        f"{tmp_path / 'prog.nc'}:2: H0: G49 H0 read as G49: H0 is no tool (Fanuc's and "
        "Centroid's rule; LinuxCNC refuses H with G49)"
    ]
    with pytest.raises(NcError, match="H2 with G49") as info:
        run(tmp_path, "G21\nG49 H2\nM2\n", LINUXCNC_START)
    assert info.value.line == 2 and info.value.word == "H2"


# ---- the config -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("gcode", "message"),
    [
        ({"m25": "home"}, "gcode.m25: must be one of refuse, z_home"),
        ({"m25": 25}, "gcode.m25: must be a string"),
        ({"main_program_m99": "loop"}, "gcode.main_program_m99: must be one of restart, end"),
        ({"main_program_m99": None}, "gcode.main_program_m99: must be a string"),
        ({"m99": "end"}, "gcode.m99"),
    ],
)
def test_the_centroid_keys_are_read_strictly(tmp_path: Path, gcode: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        mill_with_gcode(tmp_path, gcode)


def test_cncctl_check_accepts_a_centroid_post_on_xyz_mill_and_refuses_it_by_default(
    tmp_path: Path,
) -> None:
    """From outside: the shipped xyz_mill reads the post with three warnings; the same mill
    with the default rules refuses it at M25 (exit 2)."""
    prog = tmp_path / "centroid.ngc"
    prog.write_text(CENTROID_POST)
    cli = [sys.executable, "-m", "controller.operator.cli", "check", str(prog)]
    done = subprocess.run(
        [*cli, "--config", "xyz_mill", "--json"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["ok"]
    assert [w.split(": ")[1] for w in summary["warnings"]] == ["M25", "H0", "M99"]
    mill_with_gcode(tmp_path, {})  # xyz_mill with an empty gcode section: the defaults
    refused = subprocess.run(
        [*cli, "--config", str(tmp_path / "mill.yaml")], capture_output=True, text=True, timeout=120
    )
    assert refused.returncode == 2
    assert f"{prog}:16:1: error: M25 is not supported" in refused.stderr


@pytest.mark.parametrize(
    "name", sorted(p.stem for p in (REPO / "config").glob("*.yaml") if p.stem != "xyz_mill")
)
def test_the_other_shipped_configs_keep_linuxcnc_rules(name: str) -> None:
    """As docs/gcode.md says: only xyz_mill (the CAM corpus's config) reads Centroid's codes."""
    gcode = load_config(name).gcode
    assert (gcode.m25, gcode.main_program_m99) == ("refuse", "restart")
