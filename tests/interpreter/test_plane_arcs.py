"""G2/G3 in the three planes: helices in G17, G18 (ZX) and G19 (YZ) arcs, the centre words of
each plane, K0 in a G17 arc, one centre offset alone, R format; and what a config without Z
refuses."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of, motion

from controller.blocks import ArcBlock, HelixBlock
from controller.errors import NcError
from controller.geometry.helix import HelixCurve


def arcs(tmp_path: Path, text: str, config=XYZ_MILL) -> list:  # noqa: ANN001
    return [b for b in motion(blocks_of(tmp_path, text, config)) if not hasattr(b, "rapid")]


def test_a_g17_arc_with_a_z_end_is_a_helix(tmp_path: Path) -> None:
    (h,) = arcs(tmp_path, "G21 G90 F600\nG0 X10 Y0\nG3 X10 Y0 Z-2 I-10 J0 P2\n")
    assert isinstance(h, HelixBlock) and h.plane == "G17"
    assert h.center == (0.0, 0.0) and h.turns == 1
    assert h.sweep_rad == pytest.approx(4 * math.pi)
    assert h.length_mm == pytest.approx(math.hypot(40 * math.pi, 2.0))


def test_a_g17_arc_at_constant_z_stays_an_xy_arc(tmp_path: Path) -> None:
    with_k0 = arcs(tmp_path, "F600\nG2 X10 Y0 I5 J0 K0\n")
    without = arcs(tmp_path, "F600\nG2 X10 Y0 I5 J0\n")
    assert isinstance(with_k0[0], ArcBlock)
    assert with_k0[0].center == without[0].center == (5.0, 0.0)  # K0 changes nothing


def test_one_centre_offset_alone_is_the_other_zero(tmp_path: Path) -> None:
    i_only, j_only = arcs(tmp_path, "F600\nG1 X2\nG2 I-1.1\nG2 J-1.1\n")
    assert i_only.center == pytest.approx((0.9, 0.0)) and i_only.end == (2.0, 0.0, 0.0)
    assert abs(i_only.sweep_rad) == pytest.approx(2 * math.pi)
    assert j_only.center == pytest.approx((2.0, -1.1))


@pytest.mark.parametrize(("code", "words", "centre", "end"), [
    ("G18", "X10 Z0 I5", (0.0, 5.0), (10.0, 0.0, 0.0)),  # centre as (Z, X)
    ("G18", "X10 Z0 I5 K0 J0", (0.0, 5.0), (10.0, 0.0, 0.0)),
    ("G18", "X5 Z5 K5", (5.0, 0.0), (5.0, 0.0, 5.0)),
    ("G19", "Y10 Z0 J5", (5.0, 0.0), (0.0, 10.0, 0.0)),  # centre as (Y, Z)
    ("G19", "Y5 Z-5 K-5", (0.0, -5.0), (0.0, 5.0, -5.0)),
    ("G18", "X10 Z0 R5", (0.0, 5.0), (10.0, 0.0, 0.0)),
])
def test_g18_and_g19_arcs(tmp_path: Path, code: str, words: str, centre: tuple,
                          end: tuple) -> None:
    (a,) = arcs(tmp_path, f"F600\n{code} G2 {words}\n")
    assert isinstance(a, HelixBlock) and a.plane == code
    assert a.center == pytest.approx(centre, abs=1e-12) and a.end == pytest.approx(end)
    curve = HelixCurve.from_block(a)
    assert curve.points([1.0])[0] == pytest.approx(end, abs=1e-9)


def test_g18_helix_moves_along_y(tmp_path: Path) -> None:
    (a,) = arcs(tmp_path, "F600\nG18 G3 X10 Y3 Z0 I5\n")
    assert a.axial_mm == 3.0 and a.sweep_rad == pytest.approx(math.pi)
    # counter-clockwise seen from +Y, from X0 round Z0 X5: through Z+5 half way
    assert HelixCurve.from_block(a).points([0.5])[0] == pytest.approx((5.0, 1.5, 5.0))
    assert a.length_mm == pytest.approx(math.hypot(5 * math.pi, 3.0))


def test_absolute_centres_in_g18(tmp_path: Path) -> None:
    (a,) = arcs(tmp_path, "F600\nG90.1 G18 G2 X10 Z0 I5 K0\n")
    assert a.center == (0.0, 5.0)
    with pytest.raises(NcError, match="K word missing in absolute-centre arc"):
        blocks_of(tmp_path, "F600\nG90.1 G18 G2 X10 Z0 I5\n", XYZ_MILL)


@pytest.mark.parametrize(("text", "message"), [
    ("F600\nG2 X10 Y0 I5 K0.5\n", "K word in a G17 arc"),
    ("F600\nG19 G2 Y10 Z0 J5 I1\n", "I word in a G19 arc"),
    ("F600\nG18 G2 X10 Z0 I5 R5\n", "both R and K I"),
    ("F600\nG17.1\n", "UV planes"),
])
def test_refused(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(NcError, match=message):
        blocks_of(tmp_path, text, XYZ_MILL)


@pytest.mark.parametrize(("text", "word", "message"), [
    ("F600\nG2 X10 Y0 Z1 I5\n", "Z", "Z move on a machine without a Z axis"),
    ("F600\nG18\nG2 X10 I5\n", "G2", "G2 in the G18 plane needs a Z axis"),
    ("F600\nG19 G3 Y10 J5\n", "G3", "G3 in the G19 plane needs a Z axis"),
])
def test_a_config_without_z_refuses_them_naming_line_and_word(tmp_path: Path, text: str,
                                                              word: str, message: str) -> None:
    with pytest.raises(NcError, match=message) as info:
        blocks_of(tmp_path, text, XY_TABLE)
    assert info.value.word.startswith(word) and info.value.line == len(text.splitlines())


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(["G17", "G18", "G19"]), st.booleans(), st.floats(1, 40),
       st.floats(-math.pi, math.pi), st.floats(0.05, 2 * math.pi - 0.05), st.floats(-5, 5),
       st.integers(1, 3))
def test_programmed_helices_end_where_programmed(tmp_path: Path, code: str, clockwise: bool,
                                                 r: float, a0: float, sweep: float,
                                                 rise: float, turns: int) -> None:
    """Whatever the plane, direction and turns: the block's curve starts at the start, ends at
    the programmed end (a spiral where the six decimals put it off the circle), stays at the
    radius, and its length is the unrolled hypotenuse (of the mean radius)."""
    assume(code != "G17" or round(rise, 6) != 0.0)  # a G17 arc at constant Z is an ArcBlock
    first, second, normal = {"G17": "XYZ", "G18": "ZXY", "G19": "YZX"}[code]
    letters = {"G17": "IJ", "G18": "KI", "G19": "JK"}[code]
    s1, s2 = r * math.cos(a0), r * math.sin(a0)
    a1 = a0 - sweep if clockwise else a0 + sweep
    e1, e2 = r * math.cos(a1), r * math.sin(a1)
    text = (f"F600\nG0 {first}{s1:.6f} {second}{s2:.6f}\n{code} {'G2' if clockwise else 'G3'} "
            f"{first}{e1:.6f} {second}{e2:.6f} {normal}{rise:.6f} "
            f"{letters[0]}{-s1:.6f} {letters[1]}{-s2:.6f} P{turns}\n")
    (a,) = arcs(tmp_path, text)
    curve = HelixCurve.from_block(a)
    ends = curve.points([0.0, 1.0])
    assert ends[0] == pytest.approx(a.start, abs=1e-9)
    assert ends[1] == pytest.approx(a.end, abs=1e-9)
    assert abs(a.sweep_rad) == pytest.approx(sweep + 2 * math.pi * (turns - 1), abs=1e-5)
    mean_mm = a.radius_mm + 0.5 * a.radius_change_mm
    assert abs(a.radius_change_mm) < 2e-6
    assert a.length_mm == pytest.approx(math.hypot(mean_mm * a.sweep_rad, a.axial_mm),
                                        rel=1e-12)
    assert a.radius_mm == pytest.approx(r, abs=1e-5)
