"""Helices and G18/G19 arcs whose end radius differs from their start radius: planned as
LinuxCNC's spiral to the programmed end, with no step at the last sample."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from nc_helpers import XYZ_MILL, blocks_of

from controller.blocks import HelixBlock
from controller.generator.plan import generate_reference
from controller.geometry.helix import HelixCurve
from controller.interpreter.program import read_program

# the end radius 10.02 mm against the start's 10: within LinuxCNC's 0.028 mm
PROGRAMS = {
    "G18 arc": "G21 G90 F600\nG0 X10 Y0 Z0\nG18 G2 X-10.02 Z0 I-10 K0\nM2\n",
    "G19 arc": "G21 G90 F600\nG0 X0 Y10 Z0\nG19 G3 Y-10.02 Z0 J-10 K0\nM2\n",
    "G17 helix": "G21 G90 F600\nG0 X10 Y0 Z0\nG17 G3 X-10.02 Y0 Z-2 I-10 J0\nM2\n",
}


def _helix(tmp_path: Path, text: str) -> HelixBlock:
    (block,) = [b for b in blocks_of(tmp_path, text, XYZ_MILL) if isinstance(b, HelixBlock)]
    return block


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_the_curve_runs_from_the_start_to_the_programmed_end(tmp_path: Path, name: str) -> None:
    block = _helix(tmp_path, PROGRAMS[name])
    assert block.radius_change_mm == pytest.approx(0.02, abs=1e-9)
    ends = HelixCurve.from_block(block).points([0.0, 1.0])
    assert np.allclose(ends, [block.start, block.end], atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_the_plan_ends_on_the_end_point_without_a_step(tmp_path: Path, name: str) -> None:
    text = PROGRAMS[name]
    block = _helix(tmp_path, text)
    prog = tmp_path / "p.nc"
    prog.write_text(text)
    chunks = list(generate_reference(read_program(str(prog), XYZ_MILL), XYZ_MILL))
    pos = np.vstack([c.pos_mm for c in chunks])
    assert np.array_equal(pos[-1], np.array(block.end))
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    # the arc's feed is 10 mm/s: 10 um a period, and the spiral's speed along its parameter
    # is within 0.02 / (2 * 10.01) of constant; a jump to an end off the circle was 20 um
    assert steps[-20:].max() <= 10.0 * XYZ_MILL.sample_period_s * (1 + 0.02 / 20.0)


@pytest.mark.parametrize("plane", ["G17", "G18", "G19"])
@pytest.mark.parametrize("change", [-0.028, 0.0014, 0.028])
def test_a_spiral_s_derivatives_are_those_of_its_points(plane: str, change: float) -> None:
    curve = HelixCurve(plane, (1.0, -2.0), 0.5, 0.3, -4.0, 0.7, -1.5, change)
    u = np.linspace(0.05, 0.95, 7)
    h = 1e-5
    p = [curve.points(u + k * h) for k in (-1, 0, 1)]
    d = curve.evaluate(u, 2)
    assert np.allclose(d[1], (p[2] - p[0]) / (2 * h), atol=1e-6)
    assert np.allclose(d[2], (p[2] - 2 * p[1] + p[0]) / h**2, atol=1e-3)


def test_a_spiral_s_length_and_curvature_bound_its_points() -> None:
    curve = HelixCurve("G17", (0.0, 0.0), 0.5, 0.0, 3.0, 0.0, 1.5, 0.028)
    pts = curve.points(np.linspace(0.0, 1.0, 20001))
    polyline = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    assert abs(curve.length_mm - polyline) / polyline < 0.028 / (2 * 0.514)
    # the pitch c = 0.5 mm/rad lies between the radii: the curvature peaks at r = c, 1 / 2c
    assert curve.curvature_per_mm == pytest.approx(1.0 / (2 * 0.5))
    u = np.linspace(0.0, 1.0, 2001)
    d = curve.evaluate(u, 2)
    speed = np.linalg.norm(d[1], axis=1)
    kappa = np.linalg.norm(np.cross(d[1], d[2]), axis=1) / speed**3
    assert kappa.max() <= curve.curvature_per_mm * (1 + 1e-3)


def test_a_circle_s_figures_are_unchanged() -> None:
    curve = HelixCurve("G18", (0.0, 0.0), 4.0, 0.0, math.pi, 0.0, 2.0)
    assert curve.length_mm == math.hypot(4.0 * math.pi, 2.0)
    c = 2.0 / math.pi
    assert curve.curvature_per_mm == pytest.approx(4.0 / (16.0 + c * c), rel=1e-15)
