"""A window's G1 lines in one pass: the same block curves, tangents, blend quintics and run
of blended lines, bit for bit, as the per-line forms they replace (block_curve, t / abs(t)
of a Python complex, PhQuintic(...), blend_lines joint by joint)."""

from __future__ import annotations

import copy
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.blocks import ArcBlock, LineBlock, PathControl, PathMode, Source
from controller.generator.ph.construct import (
    SMOOTH_JOINT_RAD,
    BlockCurve,
    block_curve,
    block_curves,
)
from controller.generator.ph.line_blends import (
    LineJoints,
    _unit_tangents,
    blend_line_run,
    blend_lines,
    line_joints,
)
from controller.geometry.curves import LineCurve
from controller.geometry.path import Piece, PieceKind, make_piece, new_piece
from controller.geometry.ph_quintic import PhQuintic

_COORD = st.floats(-500.0, 500.0, allow_nan=False)
_PATHS = [
    PathControl(),
    PathControl(PathMode.BLEND, 0.02),
    PathControl(PathMode.EXACT_STOP),
    PathControl(PathMode.EXACT_PATH),
    PathControl(PathMode.BLEND, None, 0.01),
]
_CAP_MM_S = 50.0


def _fields(bc: object) -> tuple:
    c = bc.curve  # type: ignore[attr-defined]
    curve = (type(c), c.p0, c.p1, c.length_mm) if isinstance(c, LineCurve) else (type(c), c)
    return (
        curve,
        bc.feed_mm_s,
        type(bc.feed_mm_s),
        bc.line,  # type: ignore[attr-defined]
        bc.nurbs,
        bc.blend_tolerance_mm,
    )  # type: ignore[attr-defined]


@st.composite
def _blocks(draw: st.DrawFn) -> list:
    """Lines that follow each other (some shorter than a micrometre, feeds at, under and over
    the cap, integer feeds, path controls shared and not), with an arc now and then."""
    n = draw(st.integers(1, 40))
    x, y = draw(_COORD), draw(_COORD)
    blocks: list = []
    for i in range(n):
        if draw(st.booleans()) and draw(st.booleans()):
            dx, dy = draw(st.sampled_from([(0.0, 0.0), (1e-7, 0.0), (0.0, 3e-7)]))
        else:
            dx, dy = draw(_COORD), draw(_COORD)
        feed = draw(st.sampled_from([_CAP_MM_S, 50, 10.0, 80.0, draw(st.floats(0.1, 200.0))]))
        path = draw(st.sampled_from(_PATHS))
        if draw(st.integers(0, 9)) == 0:  # an arc: block_curve's own way
            blocks.append(
                ArcBlock(
                    (x, y, 0.0),
                    (x + 2.0, y, 0.0),
                    (x + 1.0, y),
                    True,
                    0,
                    feed,
                    path,
                    Source("p.nc", i + 1, i + 1),
                )
            )
            x += 2.0
            continue
        blocks.append(
            LineBlock(
                (x, y, 0.0), (x + dx, y + dy, 0.0), feed, False, path, Source("p.nc", i + 1, i + 1)
            )
        )
        x, y = x + dx, y + dy
    return blocks


@settings(max_examples=200, deadline=None)
@given(blocks=_blocks(), default_tol=st.sampled_from([0.0, 0.005, 0.03]))
def test_block_curves_are_block_curve_of_each_block(blocks: list, default_tol: float) -> None:
    """The same curves left out, and every field of each kept one the same, to the type of its
    feed (min returns the first of equals) and the line's length."""
    one = [bc for b in blocks if (bc := block_curve(b, _CAP_MM_S, default_tol)) is not None]
    many = block_curves(blocks, _CAP_MM_S, default_tol)
    assert [_fields(bc) for bc in many] == [_fields(bc) for bc in one]
    for bc in many:
        if isinstance(bc.curve, LineCurve):  # the length kept is the one the property gives
            c = bc.curve
            assert bc.curve.length_mm == math.hypot(c.p1[0] - c.p0[0], c.p1[1] - c.p0[1])
            assert bc.curve == LineCurve(c.p0, c.p1)


@settings(max_examples=200, deadline=None)
@given(
    ends=st.lists(
        st.tuples(_COORD, _COORD, _COORD, _COORD).filter(
            lambda e: math.hypot(e[2] - e[0], e[3] - e[1]) > 1e-6
        ),
        min_size=1,
        max_size=30,
    ),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
)
def test_unit_tangents_are_python_complex_division(ends: list, scale: float) -> None:
    """t / abs(t) of Python complexes, bit for bit (the sign of a zero part included)."""
    curves = []
    for x0, y0, x1, y1 in ends:
        p0, p1 = (x0 * scale, y0 * scale), (x1 * scale, y1 * scale)
        curves.append(type("Bc", (), {"curve": LineCurve(p0, p1)})())
    got = _unit_tangents(curves, [True] * len(curves))
    for c, t in zip(curves, got.tolist(), strict=True):
        (x0, y0), (x1, y1) = c.curve.p0, c.curve.p1
        d = complex(x1 - x0, y1 - y0)
        want = d / abs(d)
        assert (math.copysign(1.0, t.real), t.real) == (math.copysign(1.0, want.real), want.real)
        assert (math.copysign(1.0, t.imag), t.imag) == (math.copysign(1.0, want.imag), want.imag)


def test_a_curve_that_is_no_line_has_no_tangent() -> None:
    line = type("Bc", (), {"curve": LineCurve((0.0, 0.0), (3.0, 4.0))})()
    other = type("Bc", (), {"curve": object()})()
    got = _unit_tangents([other, line, other], [False, True, False])
    assert np.array_equal(got, np.array([0j, 0.6 + 0.8j, 0j]))


_W = st.complex_numbers(max_magnitude=30.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(p0=_W, w0=_W, w1=_W, w2=_W)
def test_a_made_ph_quintic_is_the_constructed_one(
    p0: complex, w0: complex, w1: complex, w2: complex
) -> None:
    """PhQuintic.made: equal to PhQuintic(...), and its sigma values and length in place are
    the ones the cached properties give."""
    made, built = PhQuintic.made(p0, w0, w1, w2), PhQuintic(p0, w0, w1, w2)
    assert made == built
    assert made.__dict__["sigma_values"] == built.sigma_values
    assert made.__dict__["length_mm"] == built.length_mm


def _piece_fields(p: Piece) -> tuple:
    c = p.curve
    curve = (
        (c.p0, c.w0, c.w1, c.w2, c.__dict__.get("sigma_values"))
        if p.kind == PieceKind.PH
        else id(c)
    )
    return (p.kind, curve, p.u0, p.u1, p.s0_mm, p.length_mm, p.feed_mm_s, p.line, p.corner)


def _by_blend_lines(first: Piece, curves: list, joints: LineJoints) -> tuple[list, int]:
    """The run joint by joint through blend_lines, each line made whole first."""
    pieces, i = [first], 1
    while i < len(curves):
        row, a, tol = joints.row.get(i), pieces[-1], curves[i - 1].blend_tolerance_mm
        if (
            row is None
            or not joints.canonical[row]
            or joints.angle_rad[row] <= SMOOTH_JOINT_RAD
            or not tol
        ):
            break
        bc = curves[i]
        b = make_piece(PieceKind.LINE, bc.curve, 0.0, 1.0, 0.0, bc.feed_mm_s, bc.line)
        blended = blend_lines(a, b, tol, joints, row)
        if blended is None:
            break
        pieces[-1:] = blended
        i += 1
    return pieces, i


@st.composite
def _polyline(draw: st.DrawFn) -> list:
    """Block curves of lines joined end to end: turns from none to reversals, lengths from
    a micrometre up, tolerances of none, zero and several sizes, feeds and lines per block."""
    n = draw(st.integers(2, 30))
    x, y, heading = 0.0, 0.0, draw(st.floats(-math.pi, math.pi))
    curves = []
    for i in range(n):
        heading += math.radians(
            draw(
                st.sampled_from(
                    [0.0, 0.3, 1.0, 30.0, -90.0, 170.0, 179.0, draw(st.floats(-180.0, 180.0))]
                )
            )
        )
        length = draw(st.sampled_from([1e-3, 0.05, 1.0, draw(st.floats(1e-3, 50.0))]))
        end = (x + length * math.cos(heading), y + length * math.sin(heading))
        tol = draw(st.sampled_from([None, 0.0, 1e-6, 0.002, 0.02, 0.5]))
        curves.append(
            BlockCurve(LineCurve((x, y), end), draw(st.floats(1.0, 80.0)), i + 1, False, tol)
        )
        x, y = end
    return curves


@settings(max_examples=300, deadline=None)
@given(curves=_polyline(), own_first=st.booleans(), trimmed=st.booleans())
def test_a_line_run_is_its_joints_blended_one_by_one(
    curves: list, own_first: bool, trimmed: bool
) -> None:
    """blend_line_run: the pieces blend_lines makes joint by joint, bit for bit, with the last
    piece before the run (whole or trimmed at its start) trimmed in place when its own."""
    joints = line_joints(curves)
    c0 = curves[0].curve
    u0 = 0.3 if trimmed else 0.0
    first = new_piece(
        PieceKind.LINE,
        c0,
        u0,
        1.0,
        0.0,
        1.0 * c0.length_mm - u0 * c0.length_mm,
        curves[0].feed_mm_s,
        curves[0].line,
        4,
    )
    want, want_end = _by_blend_lines(copy.copy(first), curves, joints)
    pieces, own = [first], [own_first]
    end = blend_line_run(pieces, own, curves, 1, joints, SMOOTH_JOINT_RAD)
    assert end == want_end
    assert [_piece_fields(p) for p in pieces] == [_piece_fields(p) for p in want]
    assert own == [own_first] if end == 1 else own == [True] * len(pieces)
    assert (pieces[0] is first) == (own_first or end == 1)
