"""The interpreter's shortcuts for the usual lines give what its general path gives: G6.2 point
lines, the NURBS split test, a G0/G1 line's box, the feed cap (blocks and errors alike)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE

from controller.blocks import LineBlock, NurbsBlock, PathControl, PathMode, Source
from controller.errors import NcError
from controller.interpreter import nurbs_blocks
from controller.interpreter.extent import line_length_and_box
from controller.interpreter.nurbs_blocks import split_at_corners
from controller.interpreter.program import read_program

HEAD = "G17 G21 G90\nF3500\n"
AIRFOIL = Path(__file__).resolve().parents[2] / "nc_programs" / "naca2415.nc"


def _outcome(path: Path) -> list[object] | tuple[int, int, str, str]:
    """The program's blocks (arrays as lists), or its error's line, column, word and message."""
    try:
        blocks = list(read_program(str(path), XY_TABLE))
    except NcError as exc:
        return exc.line, exc.col, exc.word, exc.message
    return [_plain(b) for b in blocks]


def _plain(block: object) -> object:
    if isinstance(block, NurbsBlock):
        return (
            block.degree,
            block.control_points.tolist(),
            block.weights.tolist(),
            block.knots.tolist(),
            block.z_mm,
            block.feed_mm_s,
            block.path,
            block.source,
        )
    return block


def _both_paths(tmp_path: Path, body: str) -> tuple[object, object]:
    """The program as written (plain lines: the shortcuts) and, in the same file, with a
    comment on every line (the lexer's general path, which the shortcuts must match)."""
    lines = (HEAD + body).splitlines()
    path = tmp_path / "p.nc"
    path.write_text("\n".join(lines) + "\n")
    plain = _outcome(path)
    path.write_text("\n".join(f"{t} (c)" for t in lines) + "\n")
    return plain, _outcome(path)


G6_CASES = {
    "airfoil": "".join(AIRFOIL.read_text().splitlines(keepends=True)[1:]),
    "numbered, weights": "G6.2 P3 X0 Y0 R1 K0\nN5 X1 Y1 R2 K0\nX2 Y0 R0.5 K0\nN7 X3 Y1 K1\n"
    "G6.2 K2\nK2\nK2\nG1 X0\nM2\n",
    "point after knots": "G6.2 P3 X0 Y0 K0\nX1 Y1 K0\nX2 Y0 K0\nK1\nX3 Y3 K1\nK1\nM2\n",
    "knots decrease": "G6.2 P3 X0 Y0 K0\nX1 Y1 K0\nX2 Y0 K0\nX3 Y1 K0.5\nK0.4\nK1\nK1\nM2\n",
    "too many knots": "G6.2 P2 X0 Y0 K0\nX1 Y1 K0\nX2 Y0 K1\nK2\nK2\nK2\nM2\n",
    "weights apart": "G6.2 P3 X0 Y0 R1 K0\nX1 Y1 R1 K0\nX2 Y0 R5000 K0\nK1\nK1\nK1\nM2\n",
    "weight not positive": "G6.2 P3 X0 Y0 K0\nX1 Y1 R0 K0\nX2 Y0 K0\nK1\nK1\nK1\nM2\n",
    "point without knot": "G6.2 P3 X0 Y0 K0\nX1 Y1\nM2\n",
    "Z in the block": "G6.2 P3 X0 Y0 K0\nX1 Y1 Z1 K0\nM2\n",
    "hook": "G6.2 P3 X0 Y0 K0\nX1 Y1 K0\nX1.0000001 Y1 K0\nK1\nK1\nK1\nM2\n",
    "repeated point (split)": "G6.2 P3 X0 Y0 K0\nX1 Y1 K0\nX1 Y1 K0.5\nX2 Y0 K0.5\nK1\nK1\n"
    "K1\nM2\n",
    "repeated knot (split)": "G6.2 P3 X0 Y0 K0\nX1 Y1 K0\nX2 Y0 K0\nX3 Y1 K0.5\nX4 Y0 K0.5\n"
    "K1\nK1\nK1\nM2\n",
}


@pytest.mark.parametrize("name", sorted(G6_CASES))
def test_g6_point_lines_as_the_general_path(tmp_path: Path, name: str) -> None:
    plain, commented = _both_paths(tmp_path, G6_CASES[name])
    assert plain == commented


def _block(
    points: list[tuple[float, float]], knots: list[float], weights: list[float], degree: int
) -> NurbsBlock:
    return NurbsBlock(
        degree=degree,
        control_points=np.array(points, dtype=float),
        weights=np.array(weights, dtype=float),
        knots=np.array(knots, dtype=float),
        z_mm=0.0,
        feed_mm_s=10.0,
        path=PathControl(PathMode.EXACT_STOP),
        source=Source("p.nc", 1, 9),
    )


@st.composite
def _nurbs(draw: st.DrawFn) -> NurbsBlock:
    degree = draw(st.integers(1, 4))
    n = draw(st.integers(degree + 1, degree + 6))
    grid = st.integers(0, 3).map(float)  # few values: repeated points and knots are common
    points = [(draw(grid), draw(grid)) for _ in range(n)]
    inner = sorted(
        draw(
            st.lists(st.integers(1, 3).map(float), min_size=n - degree - 1, max_size=n - degree - 1)
        )
    )
    knots = [0.0] * (degree + 1) + inner + [4.0] * (degree + 1)
    weights = [draw(st.sampled_from((1.0, 2.0))) for _ in range(n)]
    return _block(points, knots, weights, degree)


@settings(max_examples=300, deadline=None)
@given(_nurbs())
def test_split_test_as_the_full_split(block: NurbsBlock) -> None:
    """split_at_corners's test for a block it need not split leaves the same parts as the
    search for corners and standing stretches (kink_knots, still_spans) without it."""
    quick = split_at_corners(block)
    original = nurbs_blocks._smooth
    nurbs_blocks._smooth = lambda b: False
    try:
        full = split_at_corners(block)
    finally:
        nurbs_blocks._smooth = original
    assert [_plain(b) for b in quick] == [_plain(b) for b in full]


def test_split_test_finds_both_kinds_of_corner() -> None:
    smooth = _block([(0, 0), (1, 1), (2, 0), (3, 1)], [0, 0, 0, 1, 2, 2, 2], [1] * 4, 2)
    kink = _block([(0, 0), (1, 1), (2, 0), (3, 1), (4, 0)], [0, 0, 0, 1, 1, 2, 2, 2], [1] * 5, 2)
    still = _block([(0, 0), (1, 1), (1, 1), (3, 1)], [0, 0, 0, 1, 2, 2, 2], [1] * 4, 2)
    assert nurbs_blocks._smooth(smooth) and split_at_corners(smooth) == [smooth]
    assert not nurbs_blocks._smooth(kink) and len(split_at_corners(kink)) == 2
    assert not nurbs_blocks._smooth(still)


_COORD = st.sampled_from((0.0, -0.0, 1.5, -2.25, 1e-300, math.inf)) | st.floats(-1e3, 1e3)


@settings(max_examples=300, deadline=None)
@given(st.tuples(_COORD, _COORD, _COORD), st.tuples(_COORD, _COORD, _COORD))
def test_line_box_as_min_and_max(
    start: tuple[float, float, float], end: tuple[float, float, float]
) -> None:
    """Ties and signed zeros included: the same floats (and the same objects) min() and max()
    give."""
    block = LineBlock(
        start, end, 1.0, False, PathControl(PathMode.EXACT_STOP), Source("p.nc", 1, 1)
    )
    _, (lo, hi) = line_length_and_box(block)
    want_lo = tuple(min(s, e) for s, e in zip(start, end, strict=True))
    want_hi = tuple(max(s, e) for s, e in zip(start, end, strict=True))
    assert all(a is b for a, b in zip(lo, want_lo, strict=True))
    assert all(a is b for a, b in zip(hi, want_hi, strict=True))


@pytest.mark.parametrize("over", [False, True])
def test_g1_day_check_takes_the_capped_feed(tmp_path: Path, over: bool) -> None:
    """A G1 line's day-long check (inline in the G1 shortcut) reads the feed capped at the
    machine's max_feed_mm_s, as an arc's does."""
    cap_mm_s = XY_TABLE.interpolator.max_feed_mm_s
    feed_mm_min = cap_mm_s * 60 * (4 if over else 0.5)
    length_mm = math.ceil(cap_mm_s * 86_400 * 1.5)
    path = tmp_path / "long.nc"
    path.write_text(f"G1 F{feed_mm_min:.3f} X{length_mm}\nM2\n")
    with pytest.raises(NcError) as err:
        list(read_program(str(path), XY_TABLE))
    used_mm_s = min(feed_mm_min / 60, cap_mm_s)
    assert err.value.word.startswith("F") and err.value.line == 1
    assert f"at {used_mm_s * 60:g} mm/min" in err.value.message
