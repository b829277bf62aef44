"""`cncctl inspect`: its JSON form, corners and PH segments of the shipped programs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller.operator.cli import main

REPO = Path(__file__).resolve().parents[2]


def program(name: str) -> Path:
    return REPO / "nc_programs" / name


def run_json(capsys: pytest.CaptureFixture[str], name: str, *extra: str) -> dict:
    assert main(["inspect", str(program(name)), "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)


def test_naca_json(capsys: pytest.CaptureFixture[str], tmp_path) -> None:  # type: ignore[no-untyped-def]
    png = tmp_path / "naca.png"
    out = run_json(capsys, "naca2415.nc", "--plot", str(png))
    assert set(out) == {"path_length_mm", "nurbs"}
    assert out["path_length_mm"] == pytest.approx(2.0591 * 30, rel=1e-3)
    (n,) = out["nurbs"]
    assert set(n) == {"line", "degree", "control_points", "length_mm", "sharp_corners",
                      "ph_segments"}
    assert (n["line"], n["degree"], n["control_points"]) == (4, 3, 40)
    (c,) = n["sharp_corners"]
    assert set(c) == {"u_start", "u_end", "u_peak", "kappa_peak_per_mm", "x", "y"}
    assert c["kappa_peak_per_mm"] == pytest.approx(1.30, abs=0.01)
    assert c["x"] == pytest.approx(-30.0, abs=0.1)
    segs = n["ph_segments"]
    assert segs[0]["u_start"] == c["u_start"] and segs[-1]["u_end"] == c["u_end"]
    assert all(s["fit_rms_um"] <= 1.0 for s in segs)
    assert set(segs[0]) == {"u_start", "u_end", "length_mm", "fit_rms_um", "fit_max_um"}
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_butterfly_corners(capsys: pytest.CaptureFixture[str]) -> None:
    (n,) = run_json(capsys, "butterfly.nc")["nurbs"]
    kappas = sorted(c["kappa_peak_per_mm"] for c in n["sharp_corners"])
    assert kappas[-1] == pytest.approx(42.5, rel=0.02)
    assert kappas[-2] == pytest.approx(42.5, rel=0.02)
    assert kappas[-3] == pytest.approx(18.3, rel=0.01)
    assert kappas[-4] == pytest.approx(18.3, rel=0.01)


def test_text_output_and_bad_program(capsys: pytest.CaptureFixture[str], tmp_path) -> None:  # type: ignore[no-untyped-def]
    assert main(["inspect", str(program("naca2415.nc"))]) == 0
    text = capsys.readouterr().out
    assert "1 sharp corners" in text and "PH u" in text
    bad = tmp_path / "bad.nc"
    bad.write_text("G1 X1 Y1 F100\nG1 Q\n")
    assert main(["inspect", str(bad)]) == 2
    assert "bad.nc:2:" in capsys.readouterr().err
