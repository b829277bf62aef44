"""Look-ahead windows of long runs: continued without stops, bounded, flat per line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from long_helpers import airfoils, walk

from controller.config import load_config
from controller.generator import plan as plan_module
from controller.generator import replan
from controller.generator.feed.planner import plan_feed
from controller.generator.ph import construct
from controller.generator.ph.blend import blend_joint
from controller.generator.plan import WINDOW_NOMINAL_S, plan_program
from controller.generator.repeats import Bounded
from controller.generator.replan import RunStatus
from controller.generator.sampling import Interpolation, interpolate
from controller.geometry.curves import LineCurve
from controller.geometry.path import Path as ToolPath
from controller.geometry.path import PieceKind, chain, make_piece
from controller.interpreter.program import read_program
from controller.runtime.simulation import report, simulate
from controller.servo.prediction import ServoPrediction
from controller.servo.true_distance import true_error_mm

CFG = load_config(None)
T = CFG.sample_period_s


def _runs(program: Path) -> tuple[list, np.ndarray, np.ndarray]:
    steps = list(plan_program(read_program(str(program), CFG), CFG))
    ref = np.vstack([s.chunk.pos_mm for s in steps])
    feed = np.concatenate([s.chunk.feed_mm_s for s in steps])
    return [s.run for s in steps if s.run is not None], ref, feed


def test_a_long_g1_run_is_continued_from_window_to_window_without_stopping(
        tmp_path: Path) -> None:
    """1750 short G1 lines: the only cruises are through the PH blends, where the windows are
    now cut (they stopped every 200 lines before); the reference stays within Vmax and Amax
    across every cut, and the tool within the contour limit."""
    program = walk(tmp_path, 1750)
    runs, ref, feed = _runs(program)
    assert len(runs) >= 4 and all(r.status == RunStatus.OK for r in runs)
    moving = feed[int(0.05 / T):-int(0.05 / T)]
    assert moving.min() > 1.0  # no stop between the start and the end
    v = np.linalg.norm(np.diff(np.vstack([np.zeros((1, 2)), ref]), axis=0), axis=1) / T
    assert v.max() <= CFG.interpolator.max_feed_mm_s * (1 + 1e-6)
    # The planned speed keeps Amax exactly (mean value theorem); chord speeds of the reference
    # on a curve read a little more where a braking at Amax enters a blend (1e-3 of Amax: a
    # chord is shorter than its arc by (turn per sample)^2 / 24).
    assert np.abs(np.diff(feed) / T).max() <= CFG.interpolator.max_accel_mm_s2 * (1 + 1e-6)
    assert np.abs(np.diff(v) / T).max() <= CFG.interpolator.max_accel_mm_s2 * (1 + 2e-3)
    r = report(simulate(read_program(str(program), CFG), CFG, "ph-lookahead"), "w", "ph", CFG)
    assert r["contour_limit_met"]


def test_planned_samples_per_line_do_not_grow_with_the_length_of_the_run(
        tmp_path: Path) -> None:
    """What each dynamics round of a window plans (its new blocks and the overlap planned
    again) per line is the same on 1000 and on 4000 lines: nothing is carried over and grows.
    (The rounds themselves vary from window to window, 1.9 a window on average either way.)"""
    per_line = {}
    for lines in (1000, 4000):
        runs, _, _ = _runs(walk(tmp_path, lines, seed=7))
        per_line[lines] = sum(len(r.samples.s_mm) for r in runs) / lines
        assert max(len(r.geometry.path.pieces) for r in runs) < 3 * plan_module.WINDOW_BLOCKS
    assert per_line[4000] == pytest.approx(per_line[1000], rel=0.05)


def test_a_window_closes_before_a_run_is_flushed() -> None:
    """A run of MAX_RUN_BLOCKS is flushed to rest; a look-ahead window must close first, or a
    long G1 program would stop every MAX_RUN_BLOCKS lines."""
    assert plan_module.WINDOW_BLOCKS <= plan_module.MAX_RUN_BLOCKS


def test_nurbs_windows_are_bounded_by_nominal_motion_time(tmp_path: Path) -> None:
    """40 airfoils in a row (46 s): windows of about WINDOW_NOMINAL_S, not of 200 blocks."""
    runs, _, _ = _runs(airfoils(tmp_path, 40))
    assert len(runs) == 2 and all(r.status == RunStatus.OK for r in runs)
    limit = 1.5 * (WINDOW_NOMINAL_S + 1.2) / T  # a copy beyond the threshold, and the overlap
    assert max(len(r.samples.s_mm) for r in runs) < limit


def test_windows_share_repeated_curves_and_blends_but_a_short_run_does_not(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = {"blend": 0, "repeats": []}
    original_blend, original_run = construct.blend_joint, replan.plan_contour_run

    def counting_blend(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls["blend"] += 1
        return original_blend(*args, **kwargs)

    def spying_run(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls["repeats"].append(args[5] if len(args) > 5 else kwargs.get("repeats"))
        return original_run(*args, **kwargs)

    monkeypatch.setattr(construct, "blend_joint", counting_blend)
    monkeypatch.setattr(plan_module, "plan_contour_run", spying_run)
    runs, _, _ = _runs(airfoils(tmp_path, 40))
    # 39 joints of the same geometry: blended once, and once more where a window continues
    # (the joint with the previous window's prefix is a piece of its own)
    assert calls["blend"] <= len(runs)
    assert all(r is not None for r in calls["repeats"])
    curves = {id(p.curve) for r in runs for p in r.geometry.path.pieces
              if p.kind == PieceKind.NURBS}
    assert len(curves) == 1  # one interned curve for the 40 copies
    lines = [p.line for r in runs for p in r.geometry.path.pieces]
    assert len(set(lines)) == 40  # every piece keeps its own block's line
    calls["repeats"].clear()
    _runs(airfoils(tmp_path, 3))  # one window: planned as without windows, bit for bit
    assert calls["repeats"] == [None]


def test_a_window_prefix_piece_is_blended_at_its_own_end() -> None:
    """A piece of the previous window's prefix is chained (s0 > 0): the blend with the next
    block must start near that piece's end, as for the same piece at s0 = 0."""
    a = make_piece(PieceKind.LINE, LineCurve((0.0, 0.0), (2.0, 0.0)), 0.0, 1.0, 0.0, 50.0, 1)
    b = make_piece(PieceKind.LINE, LineCurve((2.0, 0.0), (2.0, 2.0)), 0.0, 1.0, 0.0, 50.0, 2)
    moved = chain([make_piece(PieceKind.LINE, LineCurve((-5.0, 0.0), (0.0, 0.0)), 0.0, 1.0,
                              0.0, 50.0, 0), a])[1]
    assert moved.s0_mm == pytest.approx(5.0)
    here, there = blend_joint(a, b, 0.03), blend_joint(moved, b, 0.03)
    assert here is not None and there is not None
    assert there[0].u1 == pytest.approx(here[0].u1, abs=1e-12)
    assert there[1].curve.p0 == pytest.approx(here[1].curve.p0, abs=1e-12)


def test_a_cut_ph_piece_is_sampled_from_its_cut() -> None:
    a = make_piece(PieceKind.LINE, LineCurve((0.0, 0.0), (2.0, 0.0)), 0.0, 1.0, 0.0, 50.0, 1)
    b = make_piece(PieceKind.LINE, LineCurve((2.0, 0.0), (2.0, 2.0)), 0.0, 1.0, 0.0, 50.0, 2)
    _, blend, _ = blend_joint(a, b, 0.03)
    ph = blend.curve
    u = 0.4
    cut = make_piece(PieceKind.PH, ph, u, 1.0, 0.0, 20.0, 2)
    path = ToolPath(chain([cut]))
    profile = plan_feed(np.array([0.0, cut.length_mm]), np.array([20.0, 20.0]), 2450.0).profile
    s = interpolate(path, profile, T, Interpolation.PH_AND_EXACT_ARC_LENGTH)
    s0 = float(ph.arc_length(np.array([u]))[0])
    xi = ph.u_of_s(s.s_mm[:-1] + s0)
    expected = ph.evaluate(xi, 0)[0]
    assert np.abs(s.xy_mm[:-1] - expected).max() < 1e-9
    assert np.linalg.norm(s.xy_mm[0] - ph.evaluate(np.array([u]), 0)[0, 0]) < 0.03


def test_the_tool_is_measured_against_the_path_before_a_window_cut() -> None:
    """A tool lagging 20 um behind on a straight line is on the path: without the reference
    before the cut, the first samples of a continuing window measured the lag to the end of a
    truncated polyline (41 um and 20 dynamics rounds on a random walk)."""
    x = np.arange(1, 201) * 0.05
    xy = np.column_stack([x, np.zeros_like(x)])
    settle = 60
    lag = np.full(len(x) + settle, 0.02)
    pred = ServoPrediction(lag, np.zeros(len(x) + settle), np.zeros(len(x) + settle))
    history = np.column_stack([np.arange(-40, 1) * 0.05, np.zeros(41)])
    cut = true_error_mm(xy, pred)
    continued = true_error_mm(xy, pred, history_xy=history)
    assert cut[0] == pytest.approx(0.02)
    assert continued[:len(x)].max() < 1e-12


def test_bounded_keeps_the_newest_entries() -> None:
    d = Bounded(3)
    for k in range(10):
        d[k] = k
    assert list(d) == [7, 8, 9]
    assert math.isclose(sum(d.values()), 24)


def test_a_section_starting_in_a_cluster_of_grid_points_stays_increasing() -> None:
    """A piece of a few nm (a stop at a trailing edge of the scaled airfoils) puts several grid
    points within the section's rounding slack of its start: the section keeps the ones after
    it (the plan failed with 'not a positive curve on an increasing grid')."""
    from controller.generator.feed.path_plan import _section

    a = 248.7359409017063
    s = np.r_[np.linspace(240.0, a - 9e-7, 5), a - 2.5e-7 + 0.5e-7 * np.arange(8), 250.0, 260.0]
    s_sec, v_sec = _section(s, np.full(len(s), 30.0), a, 260.0)
    assert s_sec[0] == a and s_sec[-1] == 260.0
    assert np.all(np.diff(s_sec) > 0) and len(v_sec) == len(s_sec)
    plain = np.array([0.0, 1.0, 2.0, 3.0])  # the usual case is left as it was
    assert np.array_equal(_section(plain, np.ones(4), 1.0, 3.0)[0], [1.0, 2.0, 3.0])


def test_a_slow_window_plans_again_only_its_last_seconds(tmp_path: Path) -> None:
    """At F1.27 the 10 mm overlap was 470 s of samples, planned again by every 30 s window:
    after a tiny circle (which keeps the windows from stopping), 10 mm took 245 MB. A window
    now plans again at most its last MIN_OVERLAP_S of motion (and still 10 mm at speed)."""
    prog = tmp_path / "slow.nc"
    prog.write_text("G21 G90 G64\nG1 X100 Y0 F2540\nG3 X100 Y0 I0.0127 J0\nG1 X90 Y0 F1.27\n"
                    "M2\n", encoding="utf-8")
    runs, ref, _ = _runs(prog)
    assert len(runs) > 10
    planned_s = [len(r.samples.xy_mm) * T for r in runs]
    assert max(planned_s) < 100.0  # was 470 s of samples per window
    # Once the circle is behind: the new blocks and a tail (at least 5 % of a window's path).
    assert max(planned_s[len(planned_s) // 2:]) < WINDOW_NOMINAL_S + 15.0
    assert np.hypot(*(ref[-1] - [90.0, 0.0])) < 1e-9


def test_a_window_continuing_a_cruise_at_the_feed_cap_plans(tmp_path: Path) -> None:
    """Feeds over the machine's cap, a window continued at the cap
    plus a rounding, and `simulate` failed ("feed planning failed: start speed above the
    limit") on a program `check` had passed."""
    prog = tmp_path / "caps.nc"
    prog.write_text("\n".join([
        "F1335.8", "G1 X-37.8125 Y36.5488", "F3388.7", "G1 X-61.1986 Y64.9995", "F1432.7",
        "G1 X-82.7123 Y81.7306", "F4918.6", "G1 X-97.0873 Y119.2896", "G1 X-125.6352 Y89.4158",
        "F535.6", "G1 X-123.3981 Y81.3115", "G1 X-117.5663 Y74.5587", "F1227.7",
        "G1 X-79.0765 Y106.7405", "F10.0", "G1 X-77.2054 Y104.3224", "F50.0",
        "G1 X-76.6816 Y103.6687", "F4533.5", "G1 X-79.3771 Y101.9638", "G1 X-111.6516 Y81.5625",
        "M2", ""]), encoding="utf-8")
    rep = report(simulate(read_program(str(prog), CFG), CFG, "ph-lookahead"), "caps",
                 "ph-lookahead", CFG)
    assert rep["contour_limit_met"]
    assert rep["max_feed_mm_s"] <= CFG.interpolator.max_feed_mm_s * (1 + 1e-9)
