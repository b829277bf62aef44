"""Arcs whose end radius differs from their start radius: planned as LinuxCNC's spiral, to the
programmed end (a CAMotics program's arc 1.4 um off its circle ended the plan 1.4 um short)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from nc_helpers import XYZ_MILL

from controller.blocks import ArcBlock, PathControl, Source
from controller.generator.long_blocks import contour_parts
from controller.generator.ph.construct import block_curve
from controller.generator.plan import END_MISS_MM, generate_reference
from controller.geometry.curves import ArcCurve
from controller.interpreter.program import read_program

CLIP = Path(__file__).resolve().parents[1] / "data" / "cam" / "camotics" / "botomata_bottom_clip.nc"


def _arcs() -> list[ArcBlock]:
    return [b for b in read_program(str(CLIP), XYZ_MILL) if isinstance(b, ArcBlock)]


def test_the_extract_has_an_arc_off_its_circle_by_more_than_the_end_miss() -> None:
    assert max(abs(a.radius_change_mm) for a in _arcs()) > END_MISS_MM


def test_every_arc_curve_of_the_extract_runs_from_its_start_to_its_programmed_end() -> None:
    for arc in _arcs():
        curve = block_curve(arc, 100.0).curve
        ends = curve.evaluate(np.array([0.0, 1.0]), 0)[0]
        assert np.allclose(ends[0], arc.start[:2], atol=1e-9, rtol=0)
        assert np.allclose(ends[1], arc.end[:2], atol=1e-9, rtol=0)


def test_the_extract_is_planned_to_its_end() -> None:
    """generate_reference raises when a run's plan ends off its programmed end."""
    chunks = list(generate_reference(read_program(str(CLIP), XYZ_MILL), XYZ_MILL))
    last = _arcs()[-1]
    xy = np.vstack([c.pos_mm[:, :2] for c in chunks])
    assert np.min(np.hypot(*(xy - last.end[:2]).T)) < 1e-9


@pytest.mark.parametrize("change", [-0.028, 0.0014, 0.028])
def test_a_spiral_s_derivatives_are_those_of_its_points(change: float) -> None:
    arc = ArcCurve((1.0, -2.0), 0.5, 0.3, -4.0, change)
    u = np.linspace(0.05, 0.95, 7)
    h = 1e-5
    p = [arc.evaluate(u + k * h, 0)[0] for k in (-1, 0, 1)]
    d = arc.evaluate(u, 2)
    assert np.allclose(d[1], (p[2] - p[0]) / (2 * h), atol=1e-6)
    assert np.allclose(d[2], (p[2] - 2 * p[1] + p[0]) / h**2, atol=1e-3)
    scalar = np.array([arc.derivatives_scalar(float(x)) for x in u])
    assert np.allclose(scalar, np.column_stack([d[1], d[2]]), atol=1e-12)


def test_a_spiral_s_length_is_its_points_length_within_the_stated_bound() -> None:
    arc = ArcCurve((0.0, 0.0), 0.5, 0.0, 3.0, 0.028)
    pts = arc.evaluate(np.linspace(0.0, 1.0, 20001), 0)[0]
    polyline = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
    assert abs(arc.length_mm - polyline) / polyline < 0.028 / (2 * 0.514)


def test_the_parts_of_a_long_spiral_lie_on_it_and_end_at_its_end() -> None:
    """A slow arc is cut into parts (long_blocks): each part starts where the spiral is."""
    r0, change = 20.0, 0.02
    end = ((r0 + change) * math.cos(3.0), (r0 + change) * math.sin(3.0), 0.0)
    arc = ArcBlock(
        (r0, 0.0, 0.0), end, (0.0, 0.0), False, 0, 0.5, PathControl(), Source("t.nc", 1, 1)
    )
    parts = list(contour_parts(arc, 100.0))
    assert len(parts) > 2
    assert parts[-1].end == end
    for k, part in enumerate(parts[1:], start=1):
        angle = math.atan2(part.start[1], part.start[0])
        assert math.hypot(*part.start[:2]) == pytest.approx(r0 + change * angle / 3.0, abs=1e-9)
        assert part.start == parts[k - 1].end
