"""controller/probe.py: where a straight probe move trips against a box (exact clipping), and
LinuxCNC's parameters of a result."""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from controller.probe import (
    PARAM_OK,
    PARAM_Z,
    ProbeResult,
    Workpiece,
    trip_point,
)

WORK = Workpiece((-20.0, -20.0, -50.0), (20.0, 20.0, 0.0))  # top face at Z0
coord = st.floats(-60, 60, allow_nan=False).map(lambda v: round(v, 3))
point = st.tuples(coord, coord, coord)


def test_probing_down_onto_the_top_face_trips_at_z0() -> None:
    assert trip_point(WORK, (5, 5, 10), (5, 5, -10), toward=True) == (5, 5, 0)
    assert trip_point(WORK, (50, 5, 10), (50, 5, -10), toward=True) is None  # beside it
    # away from the work: contact is lost where the probe leaves the box
    assert trip_point(WORK, (5, 5, -1), (5, 5, 10), toward=False) == (5, 5, 0)
    assert trip_point(WORK, (5, 5, 5), (5, 5, 10), toward=False) == (5, 5, 5)  # not in contact


@given(point, point)
def test_the_trip_is_the_first_contact_along_the_move(start: tuple, end: tuple) -> None:
    if math.dist(start, end) < 1e-3:
        return
    trip = trip_point(WORK, start, end, toward=True)
    samples = [tuple(start[i] + k / 2000 * (end[i] - start[i]) for i in range(3))
               for k in range(2001)]
    inside = [k for k, p in enumerate(samples) if WORK.contact(p)]
    if trip is None:
        assert not inside
        return
    grown = Workpiece(tuple(v - 1e-9 for v in WORK.min_mm), tuple(v + 1e-9 for v in WORK.max_mm))
    assert grown.contact(trip)  # on the box
    if inside:  # and no sampled contact before it
        first = samples[inside[0]]
        assert math.dist(start, trip) <= math.dist(start, first) + 1e-9


def test_parameters_are_the_trip_point_in_the_programs_frame() -> None:
    result = ProbeResult(7, True, (15.0, 5.0, -2.5), (15.0, 5.0, -2.6))
    params = result.parameters((10.0, 0.0, 12.5))  # G54 X10, tool length 12.5
    assert params == {5061: 5.0, 5062: 5.0, PARAM_Z: -15.0, PARAM_OK: 1.0}
    assert ProbeResult(7, False, (0, 0, 0), (0, 0, 0)).parameters((0, 0, 0))[PARAM_OK] == 0.0
