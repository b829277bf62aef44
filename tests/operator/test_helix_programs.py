"""Helical arcs and G18/G19 arcs on the 3-axis mill, from outside: `cncctl check`, `simulate` and
`run --virtual-time` on the sim card in their own processes, and the corpus programs that use
them (tests/data/cam/, see the note there). Each plan keeps every axis's velocity and the path
acceleration, and the modelled tool stays within the contour limit of the 3-D path."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helix_helpers import modelled_tool, nearest_mm
from nc_helpers import XYZ_MILL

from controller.blocks import HelixBlock, LineBlock
from controller.generator.plan import generate_reference
from controller.geometry.helix import HelixCurve
from controller.interpreter.program import read_program
from controller.servo.path_distance import block_polyline

REPO = Path(__file__).resolve().parents[2]
CNCCTL = [sys.executable, "-m", "controller.operator.cli"]
HELIX = REPO / "tests" / "data" / "helix_planes.nc"
CAM = sorted(p for p in (REPO / "tests" / "data" / "cam").iterdir()
             if p.suffix in (".nc", ".ngc", ".gcode"))
LIMIT_UM = XYZ_MILL.interpolator.contour_error_limit_mm * 1000


def cncctl(*words: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CNCCTL, *words], capture_output=True, text=True, timeout=600,
                          cwd=REPO)


def test_check_accepts_them_and_reports_the_3d_extent() -> None:
    done = cncctl("check", str(HELIX), "--config", "xyz_mill", "--json")
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads(done.stdout)
    assert summary["blocks"]["HelixBlock"] == 7
    # the G18 arcs of radius 5 about X5 Z-2.5 reach Z-7.5 and Z2.5
    assert summary["extents_mm"]["z"] == pytest.approx([-7.5, 5.0])


def test_an_xy_table_refuses_them_naming_line_and_word() -> None:
    done = cncctl("check", str(HELIX), "--config", "xy_table")
    assert done.returncode == 2
    assert f"{HELIX}:3:" in done.stderr and "Z move on a machine without a Z axis" in done.stderr


def test_simulate_and_run_on_the_sim_card() -> None:
    sim = cncctl("simulate", str(HELIX), "--config", "xyz_mill", "--json")
    assert sim.returncode == 0, sim.stderr
    planned = json.loads(sim.stdout)
    assert planned["contour_limit_met"]
    run = cncctl("run", str(HELIX), "--config", "xyz_mill", "--virtual-time", "--json")
    assert run.returncode == 0, run.stderr
    final = json.loads(run.stdout.splitlines()[-1])
    assert final["event"] == "done"
    assert final["planned_time_s"] == pytest.approx(planned["motion_time_s"], abs=1e-9)
    # measured on the card: encoder positions against the sent 3-D path, every axis
    assert final["contour_error_um"]["max"] <= LIMIT_UM
    assert final["final_position_mm"] == {"x": 0.0, "y": 10.0, "z": 5.0}
    assert all(p["commanded"] == p["executed"] for p in final["pulses"].values())


def programmed_polyline(blocks: list) -> np.ndarray:
    """The programmed 3-D path, chords within 0.1 um."""
    parts = []
    for b in blocks:
        if isinstance(b, HelixBlock):
            curve = HelixCurve.from_block(b)
            n = max(2, int(abs(b.sweep_rad) / math.sqrt(8e-4 / max(b.radius_mm, 1e-3))) + 2)
            parts.append(curve.points(np.linspace(0.0, 1.0, n)))
        elif isinstance(b, LineBlock):
            parts.append(np.array([b.start, b.end], float))
        elif (xy := block_polyline(b, 1e-4)) is not None:
            parts.append(np.column_stack([xy, np.full(len(xy), b.start[2])]))
    return np.vstack(parts)


@pytest.mark.parametrize("program", [HELIX, *CAM], ids=lambda p: p.name)
def test_every_axis_and_the_3d_contour_keep_their_limits(program: Path) -> None:
    blocks = list(read_program(str(program), XYZ_MILL))
    if program != HELIX:
        assert any(isinstance(b, HelixBlock) for b in blocks)  # why it is here
    chunks = list(generate_reference(blocks, XYZ_MILL))
    ref = np.vstack([c.pos_mm for c in chunks])
    helix_lines = [b.source.first_line for b in blocks if isinstance(b, HelixBlock)]
    on_helix = np.isin(np.concatenate([c.line for c in chunks]), helix_lines)
    T = XYZ_MILL.sample_period_s  # noqa: N806
    ip = XYZ_MILL.interpolator
    v = np.diff(np.vstack([np.zeros((1, 3)), ref]), axis=0) / T
    for i, axis in enumerate(XYZ_MILL.axes):
        assert np.abs(v[:, i]).max() <= axis.max_velocity_mm_s * (1 + 1e-6)
    for i, axis in enumerate(XYZ_MILL.axes):
        lo, hi = axis.travel_mm
        assert lo <= ref[:, i].min() and ref[:, i].max() <= hi
    a = np.linalg.norm(np.diff(np.vstack([v, np.zeros((1, 3))]), axis=0) / T, axis=1)
    # the path acceleration of the helices and G18/G19 arcs (tangential and normal together;
    # the XY contour planner's blends are not this test's subject)
    assert a[on_helix].max() <= ip.max_accel_mm_s2 * 1.01
    tool = modelled_tool(ref, np.zeros(3), XYZ_MILL)
    # on the helices and G18/G19 arcs (and the holds after them); the XY contour runs are
    # measured against their blended path by their own tests, not against programmed corners
    error_mm = nearest_mm(tool[:len(ref)][on_helix], programmed_polyline(blocks))
    assert error_mm.max() * 1000 <= LIMIT_UM
