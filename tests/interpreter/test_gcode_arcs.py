"""Property tests of the arc helpers: R-form centres, LinuxCNC radius check, arc bounding boxes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.blocks import ArcBlock, PathControl, Source
from controller.interpreter.arcs import RADIUS_TOLERANCE_MM, arc_box, center_ijk, center_r
from controller.interpreter.codes import WordError

coord = st.floats(-100, 100, allow_nan=False)
PROPS = settings(max_examples=150, deadline=None)


@PROPS
@given(coord, coord, coord, coord, st.floats(1.0, 3.0), st.booleans(), st.booleans())
def test_r_form_centre(sx: float, sy: float, ex: float, ey: float, factor: float,
                       clockwise: bool, long_way: bool) -> None:
    half = math.hypot(ex - sx, ey - sy) / 2
    if half < RADIUS_TOLERANCE_MM:  # refused as a zero-radius arc (hypothesis found 1 um)
        return
    radius = half * factor * (-1 if long_way else 1)
    cx, cy = center_r(sx, sy, ex, ey, radius, clockwise, inch=False)
    assert math.hypot(sx - cx, sy - cy) == pytest.approx(abs(radius), rel=1e-9, abs=1e-9)
    assert math.hypot(ex - cx, ey - cy) == pytest.approx(abs(radius), rel=1e-9, abs=1e-9)
    arc = ArcBlock((sx, sy, 0.0), (ex, ey, 0.0), (cx, cy), clockwise, 0, 1.0, PathControl(),
                   Source("p", 1, 1))
    sweep = abs(arc.sweep_rad)
    assert (sweep >= math.pi - 1e-6) if long_way else (sweep <= math.pi + 1e-6)
    assert (arc.sweep_rad < 0) == clockwise


TOL_MM = 2 * 0.01 * math.sqrt(2)  # LinuxCNC's CENTER_ARC_RADIUS_TOLERANCE_MM


@PROPS
@given(coord, coord, st.floats(0.5, 50), st.floats(-7, 7), st.floats(-7, 7),
       st.one_of(st.floats(-0.05, 0.05), st.floats(-4.0, 4.0)))
def test_ijk_radius_check_follows_linuxcnc(cx: float, cy: float, r: float, a0: float,
                                           a1: float, dr: float) -> None:
    if r + dr < 0.01:
        return
    sx, sy = cx + r * math.cos(a0), cy + r * math.sin(a0)
    ex, ey = cx + (r + dr) * math.cos(a1), cy + (r + dr) * math.sin(a1)
    r2 = math.hypot(ex - cx, ey - cy)
    err = abs(r2 - r)
    # interp_arc.cc: refused when over 100 x the tolerance, or over it and over 0.1 %
    refused = err > 100 * TOL_MM or (err > TOL_MM and err / max(r, r2) > 0.001)
    if not refused:
        assert center_ijk(sx, sy, ex, ey, cx, cy, inch=False) == (cx, cy)
    else:
        with pytest.raises(WordError, match="differs"):
            center_ijk(sx, sy, ex, ey, cx, cy, inch=False)


def test_a_micrometre_off_on_a_small_radius_is_accepted_as_linuxcnc_does() -> None:
    # 1.1 um on a 0.5 mm radius is 0.22 %: over the relative tolerance, under the absolute one
    assert center_ijk(0.5, 0.0, -0.5011, 0.0, 0.0, 0.0, inch=False) == (0.0, 0.0)


def test_over_a_hundred_tolerances_is_refused_whatever_the_radius() -> None:
    # 3 mm on 5000 mm is 0.06 %: under the relative tolerance, over 100 x the absolute one
    with pytest.raises(WordError, match="differs"):
        center_ijk(5000.0, 0.0, -5003.0, 0.0, 0.0, 0.0, inch=False)
    assert center_ijk(5000.0, 0.0, -5002.0, 0.0, 0.0, 0.0, inch=False) == (0.0, 0.0)


@PROPS
@given(coord, coord, st.floats(0.1, 50), st.floats(-7, 7),
       st.floats(-2 * math.pi + 1e-3, 2 * math.pi - 1e-3))
def test_arc_box_is_the_tight_box_of_the_arc(cx: float, cy: float, r: float, a0: float,
                                             sweep: float) -> None:
    sx, sy = cx + r * math.cos(a0), cy + r * math.sin(a0)
    ex, ey = cx + r * math.cos(a0 + sweep), cy + r * math.sin(a0 + sweep)
    x0, y0, x1, y1 = arc_box(sx, sy, ex, ey, cx, cy, sweep)
    ang = a0 + np.linspace(0.0, sweep, 20001)
    px, py = cx + r * np.cos(ang), cy + r * np.sin(ang)
    tol = 1e-9 * (1 + abs(cx) + abs(cy) + r)
    assert px.min() >= x0 - tol and px.max() <= x1 + tol
    assert py.min() >= y0 - tol and py.max() <= y1 + tol
    slack = r * (1 - math.cos(abs(sweep) / 20000)) + tol  # sampling misses at most this much
    assert px.min() <= x0 + slack and px.max() >= x1 - slack
    assert py.min() <= y0 + slack and py.max() >= y1 - slack
