"""G1 corners: PH blends stay within G64 P (or eps_max), G61 stops, limits hold (issue 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from controller.config import load_config
from controller.interpreter import read_program
from controller.sim_report import report, simulate

CFG = load_config()
IP = CFG.interpolator
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
