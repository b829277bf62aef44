"""Helpers for the interpreter tests: write a program to a temp file and read its blocks."""

from __future__ import annotations

from pathlib import Path

import yaml

from controller.blocks import NcBlock
from controller.config import MachineConfig, load_config
from controller.geometry.nurbs import Nurbs
from controller.interpreter.program import program_nurbs, read_program

XY_TABLE = load_config("xy_table")
XYZ_MILL = load_config("xyz_mill")


def blocks_of(tmp_path: Path, text: str, config: MachineConfig = XY_TABLE,
              name: str = "prog.nc") -> list[NcBlock]:
    """All blocks of a program given as text."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return list(read_program(str(path), config))


def motion(blocks: list[NcBlock]) -> list[NcBlock]:
    return [b for b in blocks if hasattr(b, "feed_mm_s")]


REPO = Path(__file__).resolve().parents[1]


def mill_with_gcode(tmp_path: Path, gcode: object) -> MachineConfig:
    """xyz_mill with its `gcode` section replaced (written to tmp_path/mill.yaml)."""
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["gcode"] = gcode
    path = tmp_path / "mill.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(str(path))


# xyz_mill as LinuxCNC starts: no power-up G0, no default feed
LINUXCNC_START = {"power_up_motion": "none"}


def program(name: str) -> Path:
    """A program of nc_programs/."""
    return REPO / "nc_programs" / name


def read_program_nurbs(name: str) -> Nurbs:
    """The one NURBS block of a program in nc_programs/, as a curve."""
    (curve,) = program_nurbs(str(program(name)))
    return curve
