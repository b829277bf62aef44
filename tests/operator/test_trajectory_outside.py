"""`cncctl simulate --trajectory`: an outside servo model run on the CSV's x_cmd, y_cmd gives the
contour error simulate reported (scipy.signal and the config's YAML only, none of our code)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.signal import cont2discrete, lfilter

REPO = Path(__file__).resolve().parents[2]
CNCCTL = [sys.executable, "-m", "controller.operator.cli"]
NEAR = 40  # the path is searched this many samples either side (the tool is never further off)


def _simulate(program: str, config: str, csv_path: Path) -> dict:
    done = subprocess.run([*CNCCTL, "simulate", str(REPO / program), "--config", config,
                           "--json", "--trajectory", str(csv_path)],
                          capture_output=True, text=True, timeout=300, cwd=REPO)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _columns(csv_path: Path) -> dict[str, np.ndarray]:
    with csv_path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}


def _table_ii_tool_mm(servo: dict[str, float], cmd_mm: np.ndarray, period_s: float) -> np.ndarray:
    """Eq. 27 of the paper, P/R = N/D: the tracking error E = R - P follows E/V = (D - N)/(s D)
    of the per-sample velocity V of the commanded position, zero-order held (a pulse train's
    position is a ramp within each sample). The tool starts at rest at 0."""
    d = np.array([servo[k] for k in ("a4", "a3", "a2", "a1", "a0")])
    n = np.array([0.0, 0.0, servo["b2"], servo["b1"], servo["b0"]])
    assert abs(d[-1] - n[-1]) <= 1e-9 * d[-1]  # a0 = b0: the s of (D - N)/s cancels
    b, a, _ = cont2discrete(((d - n)[:-1], d), period_s, method="zoh")
    v_mm_s = np.diff(np.r_[0.0, cmd_mm]) / period_s
    return cmd_mm - lfilter(np.squeeze(b), a, v_mm_s)


def _distance_from_path_mm(px: np.ndarray, py: np.ndarray, rx: np.ndarray,
                           ry: np.ndarray) -> np.ndarray:
    """Each tool point's distance from the wanted polyline, over the segments near its sample."""
    out = np.empty(len(px))
    last = len(rx) - 1
    for i in range(len(px)):
        lo, hi = max(0, i - NEAR), max(1, min(last, i + NEAR))
        ax, ay, dx, dy = rx[lo:hi], ry[lo:hi], np.diff(rx[lo:hi + 1]), np.diff(ry[lo:hi + 1])
        length2 = dx * dx + dy * dy
        t = np.clip(((px[i] - ax) * dx + (py[i] - ay) * dy) / np.where(length2 > 0, length2, 1),
                    0.0, 1.0)
        out[i] = np.min(np.hypot(ax + t * dx - px[i], ay + t * dy - py[i]))
    return out


@pytest.mark.parametrize("program", ["nc_programs/naca2415.nc", "nc_programs/butterfly.nc"])
def test_outside_servo_model_on_the_commands_gives_simulates_contour_error(
        program: str, tmp_path: Path) -> None:
    csv_path = tmp_path / "t.csv"
    report = _simulate(program, "xy_table", csv_path)
    cfg = yaml.safe_load((REPO / "config/xy_table.yaml").read_text())
    assert cfg["interpolator"]["servo_precompensation"] is True
    period_s = cfg["sample_period_s"]
    col = _columns(csv_path)
    assert list(col)[-2:] == ["x_cmd", "y_cmd"]
    # Every sample, the settling after the end included (the end point held, feed 0).
    assert len(col["t"]) > report["samples"]
    assert np.all(col["feed"][report["samples"]:] == 0.0)
    # Pre-compensated: what is sent leads the wanted path (by up to tens of um at speed).
    assert np.abs(col["x_cmd"] - col["x_ref"]).max() > 0.005
    tool_x = _table_ii_tool_mm(cfg["axes"]["x"]["servo"], col["x_cmd"], period_s)
    tool_y = _table_ii_tool_mm(cfg["axes"]["y"]["servo"], col["y_cmd"], period_s)
    err_um = 1e3 * _distance_from_path_mm(tool_x, tool_y, col["x_ref"], col["y_ref"])
    assert err_um.max() == pytest.approx(report["contour_error_true_um"]["max"], abs=1.0)
    rms_um = float(np.sqrt(np.mean(err_um ** 2)))
    assert rms_um == pytest.approx(report["contour_error_true_um"]["rms"], abs=0.1)
    # The CSV's own modelled tool is the same one, to well under a pulse.
    assert np.abs(tool_x - col["x_act"]).max() < 1e-4
    assert np.abs(tool_y - col["y_act"]).max() < 1e-4


def test_without_precompensation_the_commands_are_the_wanted_path(tmp_path: Path) -> None:
    csv_path = tmp_path / "t.csv"
    _simulate("nc_programs/naca2415.nc", "xy_table_paper", csv_path)
    col = _columns(csv_path)
    assert np.array_equal(col["x_cmd"], col["x_ref"])
    assert np.array_equal(col["y_cmd"], col["y_ref"])


def test_a_mill_has_a_z_command_column(tmp_path: Path) -> None:
    program = tmp_path / "z.nc"
    program.write_text("G21 G90 F600\nG1 Z-1\nG1 X5 Y2\nG1 Z0\nM2\n", encoding="utf-8")
    csv_path = tmp_path / "t.csv"
    done = subprocess.run([*CNCCTL, "simulate", str(program), "--config", "xyz_mill",
                           "--trajectory", str(csv_path)], capture_output=True, text=True,
                          timeout=120, cwd=REPO)
    assert done.returncode == 0, done.stderr
    col = _columns(csv_path)
    assert list(col)[-3:] == ["x_cmd", "y_cmd", "z_cmd"]
    assert col["z_cmd"].min() == pytest.approx(-1.0)
