"""`cncctl simulate`: its JSON form, Table IV layout, trajectory CSV, plot, bad input."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from controller.config import load_config
from controller.generator import sampling
from controller.operator.cli import main

REPO = Path(__file__).resolve().parents[2]
NACA = str(REPO / "nc_programs/naca2415.nc")
KEYS = {"program", "algorithm", "motion_time_s", "samples", "sample_period_s",
        "tracking_error_um", "contour_error_um", "max_feed_mm_s", "max_tangential_accel_mm_s2",
        "sharp_corners", "ph_segments", "ph_fit_error_um", "dynamics_rounds", "planning_cpu_s",
        "contour_error_true_um", "contour_limit_met"}


def test_json_has_every_field_of_the_issue(capsys: pytest.CaptureFixture[str],
                                           tmp_path: Path) -> None:
    csv_path, png = tmp_path / "t.csv", tmp_path / "p.png"
    assert main(["simulate", NACA, "--json", "--trajectory", str(csv_path),
                 "--plot", str(png)]) == 0
    r = json.loads(capsys.readouterr().out)
    assert KEYS <= set(r)
    assert set(r["tracking_error_um"]) == {"x", "y"}
    assert set(r["tracking_error_um"]["x"]) == {"max", "rms"}
    assert set(r["contour_error_um"]) == {"max", "rms", "mean"}
    assert set(r["ph_fit_error_um"]) == {"max", "rms"}
    assert r["algorithm"] == "ph-lookahead"
    assert r["samples"] * r["sample_period_s"] == pytest.approx(r["motion_time_s"])
    with csv_path.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "x_ref", "y_ref", "x_act", "y_act", "feed", "x_cmd", "y_cmd"]
    assert len(rows) == r["samples"] + 60 + 1  # and the 60 ms of settling simulated after them
    assert png.stat().st_size > 10_000


def test_compare_prints_table_iv_and_json_of_four(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", NACA, "--compare"]) == 0
    text = capsys.readouterr().out
    for label in ("X tracking error max", "Contour error mean", "Time (s)", "adaptive",
                  "curvature", "nurbs-lookahead", "ph-lookahead"):
        assert label in text
    assert main(["simulate", NACA, "--compare", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [r["algorithm"] for r in out["results"]] == ["adaptive", "curvature",
                                                        "nurbs-lookahead", "ph-lookahead"]


def test_bad_program_is_rejected_before_planning(capsys: pytest.CaptureFixture[str],
                                                 tmp_path: Path) -> None:
    bad = tmp_path / "bad.nc"
    bad.write_text("G21 G90 F600\nG1 X10\nG1 Y5 Q\n", encoding="utf-8")
    assert main(["simulate", str(bad), "--json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"{bad}:3:")
    assert "error:" in captured.err


def test_run_and_simulate_reject_a_program_beyond_travel(capsys: pytest.CaptureFixture[str],
                                                         tmp_path: Path) -> None:
    far = tmp_path / "far.nc"
    far.write_text("G21 G90 F600\nG1 X10\nG1 X500\nM2\n", encoding="utf-8")
    for command in (["run", str(far), "--virtual-time", "--json"], ["simulate", str(far)]):
        assert main(command) == 2
        captured = capsys.readouterr()
        assert "error: X travel limit exceeded" in captured.err
        assert captured.err.startswith(f"{far}:3:")
        assert '"event": "start"' not in captured.out  # nothing was started, nothing moved


def test_a_plan_that_breaks_the_limit_exits_1_naming_the_worst_place(
        capsys: pytest.CaptureFixture[str]) -> None:
    """adaptive runs at full feed into the trailing edge: its true error is far over 30 um."""
    assert main(["simulate", NACA, "--algorithm", "adaptive", "--json"]) == 1
    captured = capsys.readouterr()
    r = json.loads(captured.out)
    assert not r["contour_limit_met"] and r["contour_error_true_um"]["max"] > 100.0
    at = r["contour_error_true_um"]["at"]
    assert f"line {at['line']}" in captured.err and "from the path (limit 30 um)" in captured.err
    assert main(["simulate", NACA, "--json"]) == 0  # ph-lookahead keeps it, true error included
    r = json.loads(capsys.readouterr().out)
    assert r["contour_limit_met"] and r["contour_error_true_um"]["max"] <= 30.0


SQUARE = "G21 G90 G64 F600\nG1 X5\nG1 Y5\nG1 X0\nG1 Y0\nM2\n"


@pytest.mark.parametrize("kind", ["folder", "missing folder", "pipe", "empty"])
def test_an_output_that_must_not_be_written_is_refused_before_planning(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, kind: str) -> None:
    import os
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    target = {"folder": tmp_path / "adir", "missing folder": tmp_path / "nodir" / "t.csv",
              "pipe": tmp_path / "fifo", "empty": ""}[kind]
    if kind == "folder":
        os.mkdir(target)
    if kind == "pipe":
        os.mkfifo(target)
    for option in ("--trajectory", "--plot"):
        assert main(["simulate", str(program), option, str(target)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"cncctl: error: {option}") and "Traceback" not in err
    if kind in ("folder", "pipe"):  # left as it was: no rename over it, no .part beside it
        assert not os.path.isfile(target)
        assert sorted(os.listdir(tmp_path)) == sorted(["square.nc", os.path.basename(target)])


def test_a_symlinked_output_writes_its_target(tmp_path: Path) -> None:
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    (tmp_path / "link.csv").symlink_to(tmp_path / "real.csv")
    assert main(["simulate", str(program), "--trajectory", str(tmp_path / "link.csv")]) == 0
    assert (tmp_path / "link.csv").is_symlink()
    assert (tmp_path / "real.csv").read_text().startswith("t,x_ref")


def test_a_full_disk_ends_the_run_with_the_reason_and_no_part_file(
        capsys: pytest.CaptureFixture[str], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    import errno

    from controller.operator import simulate_cmd

    def full(self: simulate_cmd.TrajectoryWriter, b: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(simulate_cmd.TrajectoryWriter, "_add", full)
    program = tmp_path / "square.nc"
    program.write_text(SQUARE)
    out = tmp_path / "t.csv"
    assert main(["simulate", str(program), "--trajectory", str(out)]) == 2
    assert "--trajectory" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["square.nc"]


def test_a_nurbs_of_zero_length_is_no_motion(capsys: pytest.CaptureFixture[str],
                                             tmp_path: Path) -> None:
    """All control points at one place: nothing moves there, as for a G1 to where it stands
    (it once failed the feed planning, and faulted a run)."""
    lines = "G21 G90 G64 F600\nG1 X10\nG1 X10 Y5\n"
    plain, dot = tmp_path / "plain.nc", tmp_path / "dot.nc"
    plain.write_text(lines + "G1 X0 Y0\nM2\n")  # (a blend at the dot divided by zero)
    dot.write_text(lines + "G5.2 P1 L3\nX10 Y5 P1\nX10 Y5 P1\nG5.3\nG1 X0 Y0\nM2\n")
    times = []
    for program in (plain, dot):
        assert main(["check", str(program)]) == 0
        capsys.readouterr()
        assert main(["simulate", str(program), "--json"]) == 0
        times.append(json.loads(capsys.readouterr().out)["motion_time_s"])
    assert times[1] == times[0]


@pytest.mark.parametrize("name, body, ph_segments", [
    ("cusp", "G5.2 P1 L3\nX10 Y0 P1\nX10 Y0 P1\nX0 Y0 P1\nG5.3\n", 0),  # out and back: a stop
    ("polyline", "G5.2 P1 L2\nX20 Y0 P1\nX20 Y20 P1\nX0 Y20 P1\nX0 Y0 P1\nG5.3\n", 3),
    # a point repeated: a stretch of zero length (16.8 GB of memory, Amax x 1.4 before)
    ("repeated end", "G5.2 P1 L2\nX10 Y0 P1\nX10 Y0 P1\nG5.3\n", 0),
    ("repeated start", "G5.2 P1 L2\nX0 Y0 P1\nX0 Y-12 P1\nG5.3\n", 0),
    ("three repeated", "G5.2 L3\nX10 Y16 P1\nX-20 Y-7 P1\nX-20 Y-7 P0.1\nX-20 Y-7 P1\n"
                       "X9 Y11 P1\nX9 Y11 P1\nX-3 Y-10 P1\nX-3 Y-10 P1\nG5.3\n", None),
])
def test_corners_inside_a_nurbs_keep_amax_and_the_limit(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str, body: str,
        ph_segments: int | None) -> None:
    """A NURBS whose tangent jumps at a knot (a cusp, a degree-1 polyline) was passed at speed:
    a velocity step (Amax broken at the cusp) or rounds of slowing down. Now it is split there
    and the corner is blended or stopped at, as between G1 lines."""
    program = tmp_path / f"{name}.nc"
    program.write_text("G21 G90 G64 F3000\n" + body + "M2\n")
    assert main(["simulate", str(program), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    amax = load_config("xy_table").interpolator.max_accel_mm_s2
    assert r["max_tangential_accel_mm_s2"] <= amax * 1.001
    assert r["dynamics_rounds"] == 1
    assert ph_segments is None or r["ph_segments"] == ph_segments


def test_a_plan_that_cannot_be_right_is_an_error_not_gigabytes(
        capsys: pytest.CaptureFixture[str], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A cusp next to a weight of 0.01 once planned 13,993,004 s of motion (104 GiB of samples
    asked for; it now plans, tests/generator/test_uneven_nurbs.py). Such a plan is refused by
    name, whatever lets it through: here a guard lowered under a 0.6 s line stands in."""
    monkeypatch.setattr(sampling, "MAX_PLANNED_RUN_S", 0.3)
    program = tmp_path / "line.nc"
    program.write_text("G1 X10 Y0 F1000\nM2\n")
    assert main(["simulate", str(program)]) == 2
    err = capsys.readouterr().err
    assert "the path could not be planned" in err and "Traceback" not in err


def test_a_short_program_is_planned_from_its_check_a_long_one_read_again(
        capsys: pytest.CaptureFixture[str], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """simulate plans the blocks its check kept; past KEEP_BLOCKS it reads the program again
    (memory bounded) and reports the same."""
    from controller.interpreter import program as interp_program
    from controller.operator import simulate_cmd

    prog = tmp_path / "steps.nc"
    prog.write_text("G21 F600\n" + "".join(f"G1 X{i % 7} Y{i % 5}\n" for i in range(1, 40))
                    + "M2\n")
    reads: list[str] = []
    real_read = interp_program.read_program

    def counted(path: str, *args: object, **kw: object):  # type: ignore[no-untyped-def]
        reads.append(path)
        return real_read(path, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr("controller.operator.check_cmd.read_program", counted)
    monkeypatch.setattr(simulate_cmd, "read_program", counted)
    reports = []
    # 41 blocks, 39 of them lines: kept as blocks, kept with lines past the 10th as numbers,
    # then over the limit
    for keep, keep_lines, n_reads in ((1000, 1000, 1), (10, 1000, 1), (10, 10, 2)):
        monkeypatch.setattr(simulate_cmd, "KEEP_BLOCKS", keep)
        monkeypatch.setattr(simulate_cmd, "KEEP_LINES", keep_lines)
        reads.clear()
        assert main(["simulate", str(prog), "--json"]) == 0
        reports.append(json.loads(capsys.readouterr().out))
        assert len(reads) == n_reads
    for r in reports:
        del r["planning_cpu_s"]
    assert reports[0] == reports[1] == reports[2]
