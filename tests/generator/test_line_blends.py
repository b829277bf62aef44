"""A long program's G1 line joints, blended all at once by their unit blend (line_blends.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.generator.ph.blend import blend_joint
from controller.generator.ph.construct import BlockCurve
from controller.generator.ph.line_blends import applies, blend_lines, line_joints
from controller.geometry.curves import LineCurve
from controller.geometry.path import Piece, PieceKind, make_piece


def _joint(turn_deg: float, la: float, lb: float, heading: float
           ) -> tuple[Piece, Piece, np.ndarray]:
    corner = (3.0, -2.0)
    start = (corner[0] - la * math.cos(heading), corner[1] - la * math.sin(heading))
    out = heading + math.radians(turn_deg)
    end = (corner[0] + lb * math.cos(out), corner[1] + lb * math.sin(out))
    a = make_piece(PieceKind.LINE, LineCurve(start, corner), 0.0, 1.0, 0.0, 50.0, 1)
    b = make_piece(PieceKind.LINE, LineCurve(corner, end), 0.0, 1.0, 0.0, 50.0, 2)
    return a, b, np.array([start, corner, end])


def _distance_to(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    a, ab = poly[:-1], np.diff(poly, axis=0)
    rel = pts[:, None, :] - a[None]
    t = np.clip(np.einsum("pij,ij->pi", rel, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * ab[None], axis=2).min(axis=1)


@settings(max_examples=100, deadline=None)
@given(turn_deg=st.floats(1.0, 159.0), la=st.floats(0.05, 20.0), lb=st.floats(0.05, 20.0),
       tol_mm=st.floats(1e-4, 0.05), heading=st.floats(-math.pi, math.pi))
def test_the_unit_blend_scaled_is_the_bisected_blend(turn_deg: float, la: float, lb: float,
                                                     tol_mm: float, heading: float) -> None:
    """The largest cut that fits, found exactly (the single run's 30 halvings agree to theirs),
    the same PH quintic, within the tolerance measured densely, and joined to both lines."""
    a, b, poly = _joint(turn_deg, la, lb, heading)
    joints = line_joints([BlockCurve(a.curve, 50.0, 1, False, tol_mm),
                          BlockCurve(b.curve, 50.0, 2, False, tol_mm)])
    assert joints.row == {1: 0}
    assert joints.angle_rad[0] == pytest.approx(math.radians(turn_deg), abs=1e-9)
    assert applies(a, b, joints, 0)
    single, fast = blend_joint(a, b, tol_mm), blend_lines(a, b, tol_mm, joints, 0)
    assert (single is None) == (fast is None)
    if fast is None:
        return
    cut = a.length_mm - fast[0].length_mm
    halving = 0.45 * min(la, lb) / 2 ** 30  # where the bisection leaves it
    assert cut == pytest.approx(a.length_mm - single[0].length_mm, rel=1e-9, abs=2 * halving)
    assert b.length_mm - fast[2].length_mm == pytest.approx(cut, rel=1e-9)
    xi = np.linspace(0.0, 1.0, 4001)
    pts = fast[1].curve.evaluate(xi, 0)[0]
    assert np.abs(pts - single[1].curve.evaluate(xi, 0)[0]).max() <= 4 * halving + 1e-9 * cut
    assert _distance_to(poly, pts).max() <= tol_mm * (1 + 1e-4)
    ends = [fast[0].curve.evaluate(np.array([fast[0].u1]), 0)[0, 0],
            fast[2].curve.evaluate(np.array([fast[2].u0]), 0)[0, 0]]
    assert np.abs(pts[0] - ends[0]).max() < 1e-12 and np.abs(pts[-1] - ends[1]).max() < 1e-12


def test_sharp_turns_and_cut_pieces_go_the_general_way() -> None:
    """Beyond ~160 degrees the canonical interpolant is not the best one, and a piece already
    cut at the joint (a window's prefix) is not a whole line: blend.py takes those."""
    a, b, _ = _joint(170.0, 2.0, 2.0, 0.3)
    joints = line_joints([BlockCurve(a.curve, 50.0, 1, False, 0.03),
                          BlockCurve(b.curve, 50.0, 2, False, 0.03)])
    assert not applies(a, b, joints, 0)
    a, b, _ = _joint(90.0, 2.0, 2.0, 0.3)
    joints = line_joints([BlockCurve(a.curve, 50.0, 1, False, 0.03),
                          BlockCurve(b.curve, 50.0, 2, False, 0.03)])
    assert applies(a, b, joints, 0)
    cut = make_piece(PieceKind.LINE, a.curve, 0.0, 0.9, 0.0, 50.0, 1)
    assert not applies(cut, b, joints, 0)
