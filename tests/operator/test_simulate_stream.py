"""`cncctl simulate` streaming: the trajectory CSV as it goes, plot series, --stats."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from long_helpers import walk

from controller.config import load_config
from controller.errors import PlanningError
from controller.interpreter.program import read_program
from controller.operator import simulate_cmd
from controller.operator.cli import main
from controller.operator.simulate_plot import MAX_POINTS, PlotSeries
from controller.runtime.simulate_stream import SampleBlock
from controller.runtime.simulation import simulate
from controller.servo.precompensation import Precompensator

REPO = Path(__file__).resolve().parents[2]
NACA = str(REPO / "nc_programs/naca2415.nc")
CFG = load_config(None)


def test_the_streamed_csv_is_the_one_written_from_the_whole_arrays(tmp_path: Path) -> None:
    """Byte for byte what csv.writer wrote from the whole trajectory before (%.9g, CRLF)."""
    program = str(walk(tmp_path, 250))
    out = tmp_path / "t.csv"
    assert main(["simulate", program, "--json", "--trajectory", str(out)]) in (0, 1)
    traj = simulate(read_program(program, CFG), CFG, "ph-lookahead")
    expected = tmp_path / "expected.csv"
    n, m = len(traj.t_s), len(traj.ex_mm)  # reference samples, and the settling after them
    ref = np.vstack([traj.ref_mm, np.repeat(traj.ref_mm[-1:], m - n, axis=0)])
    servos = [a.servo if a.name in ("x", "y") else None for a in CFG.axes]
    cmd = Precompensator(servos, CFG.sample_period_s, np.zeros(2)).push(ref)
    with expected.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x_ref", "y_ref", "x_act", "y_act", "feed", "x_cmd", "y_cmd"])
        rows = np.column_stack([np.arange(1, m + 1) * CFG.sample_period_s, ref[:, 0],
                                ref[:, 1], ref[:, 0] - traj.ex_mm, ref[:, 1] - traj.ey_mm,
                                np.r_[traj.feed_mm_s, np.zeros(m - n)], cmd])
        w.writerows([f"{v:.9g}" for v in row] for row in rows)
    assert out.read_bytes() == expected.read_bytes()
    assert not (tmp_path / "t.csv.part").exists()


def test_a_failed_run_leaves_no_trajectory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    real = simulate_cmd.simulate_stream

    def failing(blocks, config, algorithm, sinks, on_run=None):  # noqa: ANN001, ANN202
        def first_then_fail(b: SampleBlock) -> None:
            for sink in sinks:
                sink(b)
            raise PlanningError("line 9: planning failed on purpose")
        return real(blocks, config, algorithm, [first_then_fail], on_run)

    monkeypatch.setattr(simulate_cmd, "simulate_stream", failing)
    out = tmp_path / "t.csv"
    assert main(["simulate", NACA, "--trajectory", str(out)]) == 2
    assert "planning failed on purpose" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "t.csv.part").exists()


def test_stats_tell_windows_and_rounds_and_leave_the_report_alone(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    program = str(walk(tmp_path, 1150))
    assert main(["simulate", program, "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(["simulate", program, "--json", "--stats"]) == 0
    with_stats = json.loads(capsys.readouterr().out)
    stats = with_stats.pop("stats")
    assert "stats" not in plain
    plain.pop("planning_cpu_s"), with_stats.pop("planning_cpu_s")
    assert with_stats == plain
    assert stats["windows"] >= 3 and stats["dynamics_rounds_max"] == plain["dynamics_rounds"]
    assert 1.0 <= stats["dynamics_rounds_mean"] <= stats["dynamics_rounds_max"]


def _block(i0: int, n: int, contour_mm: np.ndarray) -> SampleBlock:
    z = np.zeros(n)
    return SampleBlock(i0, n, np.zeros((n, 2)), np.full(n, 10.0), np.zeros(n, np.int32), z, z,
                       contour_mm, np.ones(n, bool), z)


def test_the_plot_series_of_a_long_program_is_bounded_and_keeps_the_peaks() -> None:
    series = PlotSeries(CFG)
    rng = np.random.default_rng(2)
    n, block = 1_000_000, 7919
    peak_at = 654_321
    for i0 in range(0, n, block):
        m = min(block, n - i0)
        e = rng.normal(scale=1e-3, size=m)
        if i0 <= peak_at < i0 + m:
            e[peak_at - i0] = -0.05
        series.add(_block(i0, m, e))
    feed_t, feed, err_t, err_um = series.arrays()
    assert len(feed) <= 2 * MAX_POINTS + block and len(err_um) == len(err_t)
    k = int(np.argmin(err_um))
    assert err_um[k] == pytest.approx(-50.0) and err_t[k] == pytest.approx((peak_at + 1) * 1e-3)
    assert np.all(np.diff(feed_t) > 0)


def test_a_plot_of_a_short_program_has_every_sample(tmp_path: Path) -> None:
    series = PlotSeries(CFG)
    e = np.linspace(-0.01, 0.01, 500)
    series.add(_block(0, 500, e))
    _, feed, _, err_um = series.arrays()
    assert np.array_equal(err_um, e * 1000.0) and len(feed) == 500
    png = tmp_path / "p.png"
    assert main(["simulate", NACA, "--compare", "--plot", str(png)]) == 0
    assert png.stat().st_size > 10_000
