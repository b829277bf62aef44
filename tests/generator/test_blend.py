"""G1 corners: PH blends stay within G64 P (or eps_max), G61 stops, limits hold."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.blocks import NurbsBlock
from controller.config import load_config
from controller.generator.ph import blend
from controller.generator.ph.blend import blend_joint
from controller.geometry.curves import LineCurve
from controller.geometry.nurbs import Nurbs
from controller.geometry.path import Piece, PieceKind, make_piece
from controller.interpreter.program import read_program
from controller.runtime.simulation import report, simulate

CFG = load_config()
IP = CFG.interpolator
NACA = str(Path(__file__).resolve().parents[2] / "nc_programs/naca2415.nc")
CORNERS = [(0, 0), (50, 0), (50, 30), (80, 30), (80, -30), (20, -40), (0, 0)]


def _program(tmp_path: Path, mode: str) -> str:
    lines = ["G17 G21 G90 F3000", mode]
    lines += [f"G1 X{x} Y{y}" for x, y in CORNERS[1:]]
    path = tmp_path / "corners.nc"
    path.write_text("\n".join([*lines, "M2", ""]), encoding="utf-8")
    return str(path)


def _distance_to_polyline_mm(pts: np.ndarray) -> np.ndarray:
    poly = np.array(CORNERS, float)
    a, b = poly[:-1], poly[1:]
    ab = b - a
    rel = pts[:, None, :] - a[None]
    t = np.clip(np.einsum("pij,ij->pi", rel, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    near = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(pts[:, None, :] - near, axis=2).min(axis=1)


@pytest.mark.parametrize(("mode", "tolerance_mm"), [("G64 P0.05", 0.05), ("G64 P0.01", 0.01),
                                                    ("G64", IP.contour_error_limit_mm)])
def test_blends_stay_within_the_path_tolerance(tmp_path: Path, mode: str,
                                               tolerance_mm: float) -> None:
    traj = simulate(read_program(_program(tmp_path, mode), CFG), CFG, "ph-lookahead")
    r = report(traj, "corners", "ph-lookahead", CFG)
    dev = _distance_to_polyline_mm(traj.ref_mm)
    assert dev.max() <= tolerance_mm * (1 + 1e-6)
    assert dev.max() >= 0.2 * tolerance_mm  # the corners really are rounded, not stopped at
    assert r["ph_segments"] == len(CORNERS) - 2
    assert r["contour_error_um"]["max"] <= IP.contour_error_limit_mm * 1000
    assert r["max_tangential_accel_mm_s2"] <= IP.max_accel_mm_s2 * (1 + 1e-6)
    assert r["max_feed_mm_s"] <= 50.0 * (1 + 1e-9)  # F3000 mm/min
    assert np.array_equal(traj.ref_mm[-1], [0.0, 0.0])


def test_exact_stop_mode_stops_at_every_corner(tmp_path: Path) -> None:
    traj = simulate(read_program(_program(tmp_path, "G61"), CFG), CFG, "ph-lookahead")
    assert _distance_to_polyline_mm(traj.ref_mm).max() < 1e-9
    for corner in CORNERS[1:-1]:
        k = int(np.argmin(np.linalg.norm(traj.ref_mm - corner, axis=1)))
        assert np.linalg.norm(traj.ref_mm[k] - corner) < 1e-9  # passes exactly through it
        assert traj.feed_mm_s[k] < 1.0  # ... at (nearly) zero feed


def test_blending_is_faster_than_exact_stop(tmp_path: Path) -> None:
    times = {mode: report(simulate(read_program(_program(tmp_path, mode), CFG), CFG,
                                   "ph-lookahead"), "c", "ph", CFG)["motion_time_s"]
             for mode in ("G61", "G64 P0.05")}
    assert times["G64 P0.05"] < times["G61"]


def test_long_contour_is_planned_in_windows_without_stopping(tmp_path: Path) -> None:
    """A 1440-block G64 polyline: several look-ahead windows, continued mid-cruise."""
    ang = np.linspace(0.0, 8.0 * np.pi, 1441)
    pts = np.column_stack([20.0 * np.cos(ang) - 20.0, 12.0 * np.sin(ang)])
    lines = ["G17 G21 G90 F3000", "G64 P0.01"] + [f"G1 X{x:.4f} Y{y:.4f}" for x, y in pts[1:]]
    prog = tmp_path / "spiral.nc"
    prog.write_text("\n".join([*lines, "M2", ""]), encoding="utf-8")
    from controller.generator.plan import plan_program

    steps = list(plan_program(read_program(str(prog), CFG), CFG, "ph-lookahead"))
    assert len(steps) >= 3  # really planned in windows (of WINDOW_BLOCKS = 500)
    ref = np.vstack([s.chunk.pos_mm for s in steps])
    t = np.concatenate([s.chunk.t0_s + np.arange(len(s.chunk)) * CFG.sample_period_s
                        for s in steps])
    assert np.allclose(np.diff(t), CFG.sample_period_s)
    speed = np.linalg.norm(np.diff(np.vstack([[0.0, 0.0], ref]), axis=0), axis=1) / 0.001
    assert speed[200:-200].min() > 0.95 * 50.0  # no stop at the window seams
    accel = np.diff(speed) / 0.001
    # Chord speeds on a curve read slightly off the arc's (see test_windows); the planned
    # speed keeps Amax exactly.
    feed = np.concatenate([s.chunk.feed_mm_s for s in steps])
    assert np.abs(np.diff(feed) / 0.001).max() <= IP.max_accel_mm_s2 * (1 + 1e-6)
    assert np.abs(accel).max() <= IP.max_accel_mm_s2 * (1 + 2e-3)
    assert speed.max() <= 50.0 * (1 + 1e-9)
    poly_dev = _distance_to_points_polyline(ref, pts)
    assert poly_dev.max() <= 0.01 * (1 + 1e-6)
    assert np.array_equal(ref[-1], np.round(pts[-1], 4) + 0.0)
    r = report(simulate(read_program(str(prog), CFG), CFG, "ph-lookahead"), "s", "ph", CFG)
    assert r["contour_error_um"]["max"] <= IP.contour_error_limit_mm * 1000


def _distance_to_points_polyline(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    a, b = poly[:-1], poly[1:]
    ab = b - a
    out = np.full(len(pts), np.inf)
    for i0 in range(0, len(pts), 2000):
        p = pts[i0:i0 + 2000]
        rel = p[:, None, :] - a[None]
        t = np.clip(np.einsum("pij,ij->pi", rel, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
        near = a[None] + t[..., None] * ab[None]
        out[i0:i0 + 2000] = np.linalg.norm(p[:, None, :] - near, axis=2).min(axis=1)
    return out


# --- a long program's windows: the cut searched to 1 % (generator/repeats.py) ----------------

def _counted(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    trials = [0]
    original = blend._trial

    def counting(*args):  # noqa: ANN002, ANN202
        trials[0] += 1
        return original(*args)

    monkeypatch.setattr(blend, "_trial", counting)
    return trials


def _line(p0: tuple[float, float], p1: tuple[float, float]) -> Piece:
    return make_piece(PieceKind.LINE, LineCurve(p0, p1), 0.0, 1.0, 0.0, 50.0, 1)


def _cut_mm(found: tuple[Piece, Piece, Piece], a: Piece) -> float:
    return a.length_mm - found[0].length_mm


@settings(max_examples=60, deadline=None)
@given(turn_deg=st.floats(5.0, 170.0), la=st.floats(0.05, 20.0), lb=st.floats(0.05, 20.0),
       tol_mm=st.floats(1e-4, 0.05), heading=st.floats(-math.pi, math.pi))
def test_a_windowed_line_blend_fits_within_a_percent_of_the_bisected_cut(
        turn_deg: float, la: float, lb: float, tol_mm: float, heading: float) -> None:
    """The search (power-law aim, then a step past a cut that fits) ends within 1 % of the
    largest cut that fits (the single run's 30 halvings find it to 1e-9), always within the
    tolerance, and in one trial: a line joint's deviation grows exactly as its cut."""
    corner = (3.0, -2.0)
    start = (corner[0] - la * math.cos(heading), corner[1] - la * math.sin(heading))
    out = heading + math.radians(turn_deg)
    end = (corner[0] + lb * math.cos(out), corner[1] + lb * math.sin(out))
    a, b = _line(start, corner), _line(corner, end)
    single = blend_joint(a, b, tol_mm)
    with pytest.MonkeyPatch.context() as mp:
        trials = _counted(mp)
        windowed = blend_joint(a, b, tol_mm, precision=0.01)
    assert (single is None) == (windowed is None)
    if single is None:
        return
    assert trials[0] == 1
    cut, best = _cut_mm(windowed, a), _cut_mm(single, a)
    assert best / 1.01 * (1 - 1e-9) <= cut <= best * (1 + 1e-9)
    poly = np.array([start, corner, end])
    pts = windowed[1].curve.evaluate(np.linspace(0.0, 1.0, 2001), 0)[0]
    assert _distance_to(poly, pts).max() <= tol_mm * (1 + 1e-6)


def test_a_windowed_airfoil_joint_is_blended_in_a_third_of_the_trials(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The trailing edge between two airfoils (NURBS to NURBS): the windowed blend samples
    its path in u (no arc-length inverse), fits within the tolerance, and finds a cut within
    2 % of the bisected one in at most 2 trials where bisection takes 31."""
    curve = Nurbs.from_block(next(b for b in read_program(NACA, CFG)
                                  if isinstance(b, NurbsBlock)))
    a = make_piece(PieceKind.NURBS, curve, 0.5 * curve.u_end, curve.u_end, 0.0, 50.0, 1)
    b = make_piece(PieceKind.NURBS, curve, curve.u_start, 0.5 * curve.u_end, 0.0, 50.0, 2)
    tol = IP.contour_error_limit_mm
    trials = _counted(monkeypatch)
    single = blend_joint(a, b, tol)
    single_trials, trials[0] = trials[0], 0
    windowed = blend_joint(a, b, tol, precision=0.01)
    assert single is not None and windowed is not None
    assert single_trials == 31 and trials[0] <= 2
    assert _cut_mm(windowed, a) == pytest.approx(_cut_mm(single, a), rel=0.02)
    pts = windowed[1].curve.evaluate(np.linspace(0.0, 1.0, 2001), 0)[0]
    # The curve near the joint (a tenth of it at each end, where both surfaces meet at the
    # trailing edge), as densely as 200k points over the whole: the blend lies there.
    span = curve.u_end - curve.u_start
    near = [np.linspace(curve.u_start, curve.u_start + 0.1 * span, 20_001),
            np.linspace(curve.u_end - 0.1 * span, curve.u_end, 20_001)]
    assert windowed[0].u1 > curve.u_end - 0.1 * span and windowed[2].u0 < near[0][-1]
    dist = np.minimum(*(_distance_to(curve.evaluate(u, 0)[0], pts) for u in near))
    assert dist.max() <= tol * (1 + 1e-3)
    # the trimmed pieces end where the blend starts and start where it ends
    ends = curve.evaluate(np.array([windowed[0].u1, windowed[2].u0]), 0)[0]
    assert np.abs(ends[0] - windowed[1].curve.evaluate(np.array([0.0]), 0)[0, 0]).max() < 1e-12
    assert np.abs(ends[1] - windowed[1].curve.evaluate(np.array([1.0]), 0)[0, 0]).max() < 1e-9


def _distance_to(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    a, b = poly[:-1], poly[1:]
    ab = b - a
    out = np.full(len(pts), np.inf)
    for k in range(0, len(pts), 200):  # chunks: a dense polyline is 200k segments
        p = pts[k:k + 200]
        rel = p[:, None, :] - a[None]
        t = np.clip(np.einsum("pij,ij->pi", rel, ab) / np.maximum(
            np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
        near = a[None] + t[..., None] * ab[None]
        out[k:k + 200] = np.linalg.norm(p[:, None, :] - near, axis=2).min(axis=1)
    return out


def _deviation_einsum(ph, poly: np.ndarray, n: int = 65) -> float:  # type: ignore[no-untyped-def]
    """deviation_mm as it was written on (points, segments, 2) arrays: the reference."""
    pts = ph.point(np.linspace(0.0, 1.0, n))
    pts = np.column_stack([pts.real, pts.imag])
    a, b = poly[:-1], poly[1:]
    ab = b - a
    rel = pts[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("pij,ij->pi", rel, ab)
                / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return float(np.min(np.linalg.norm(pts[:, None, :] - nearest, axis=2), axis=1).max())


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 140), st.booleans())
def test_deviation_on_x_and_y_equals_the_einsum_form(seed: int, m: int, repeat: bool) -> None:
    """A trial's deviation, computed on x and y apart, is the (points, segments, 2) form's
    number bit for bit: random blends against random polylines, a zero-length segment too."""
    from controller.geometry.ph_quintic import PhQuintic

    rng = np.random.default_rng(seed)
    ph = PhQuintic.hermite(complex(*rng.normal(0, 5, 2)), complex(*rng.normal(0, 5, 2)),
                           complex(*rng.normal(0, 3, 2)), complex(*rng.normal(0, 3, 2)))
    poly = np.cumsum(rng.normal(0, 1, (m, 2)), axis=0)
    if repeat:
        poly[m // 2] = poly[m // 2 - 1]
    assert blend.deviation_mm(ph, poly) == _deviation_einsum(ph, poly)
