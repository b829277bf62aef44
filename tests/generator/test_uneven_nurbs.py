"""NURBS whose parametric speed is very uneven: the feed-limit grid still sees their whole length
and the curvature at their knots, and the plan keeps the tool within the contour limit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from nc_helpers import XY_TABLE, blocks_of

from controller.generator.feed import grid, path_plan
from controller.geometry.nurbs import Nurbs
from controller.geometry.path import Path as ToolPath
from controller.geometry.path import PieceKind, make_piece
from controller.runtime.simulation import limit_um, report, simulate

# A quadratic with knot spans 1 and 9999 (within the interpreter's factor 10000): its first span
# is 5.1 mm of path in one parameter unit, the rest 10 mm in 9999; at the knot it turns 22
# degrees within 0.5 um (curvature 3.8e6 /mm from the left, 0.019 /mm from the right).
UNEVEN = """G21 G90
G1 X0 Y0 F1000
G6.2 P3 X0 Y0 R1 K0
X5 Y1 R1 K0
X10 Y0 R1 K0
X15 Y0 R1 K1
K{end}
K{end}
K{end}
M2
"""


def _curve(end: float) -> Nurbs:
    return Nurbs(2, np.array([0.0, 0.0, 0.0, 1.0, end, end, end]),
                 np.array([[0.0, 0.0], [5.0, 1.0], [10.0, 0.0], [15.0, 0.0]]), np.ones(4))


def _grid(curve: Nurbs) -> tuple[np.ndarray, np.ndarray]:
    piece = make_piece(PieceKind.NURBS, curve, curve.u_start, curve.u_end, 0.0, 16.0, 3)
    return grid.limit_samples(ToolPath((piece,)))


def test_the_grid_covers_every_knot_span_and_the_knot_curvature() -> None:
    s, kappa = _grid(_curve(1e4))
    spacing = grid.grid_step_mm(ToolPath((make_piece(
        PieceKind.NURBS, _curve(1e4), 0.0, 1e4, 0.0, 16.0, 3),)))
    # Even parameters put one sample on the first 5.1 mm. By knot span, even parameters in a
    # span whose speed falls from 10 to 0.001 are at most twice their mean spacing apart.
    assert float(np.diff(s).max()) <= 2.0 * spacing
    assert np.all(np.diff(s) > 0.0)
    # The left side's curvature at the knot is on the grid, where the path is at the knot.
    k = int(np.argmax(kappa))
    assert kappa[k] > 3.7e6
    assert s[k] == pytest.approx(float(_curve(1e4).s_of_u(np.array([1.0]))[0]), abs=1e-9)
    assert s[-1] == pytest.approx(_curve(1e4).length_mm, rel=1e-12)


def test_an_even_nurbs_keeps_its_even_grid() -> None:
    """The airfoil and the other programs' NURBS are resolved by even parameters: their grid,
    and so their plans, are as before (the golden test checks the plans themselves)."""
    even = _curve(2.0)
    piece = make_piece(PieceKind.NURBS, even, 0.0, 2.0, 0.0, 16.0, 3)
    s, kappa = grid.limit_samples(ToolPath((piece,)))
    n = len(s)
    u = np.linspace(0.0, 2.0, n)
    expected = grid._speed_and_kappa(even, u)[1]
    assert np.array_equal(kappa, expected)


@pytest.mark.parametrize("end", [1000, 9999])
def test_an_uneven_nurbs_is_planned_within_the_contour_limit(tmp_path: Path, end: int) -> None:
    """At 9999 the tool was 34.6 um from the path (limit 30) after 20 dynamics rounds: the
    grid never saw the turn, so the feed passed it at 16.7 mm/s."""
    blocks = blocks_of(tmp_path, UNEVEN.format(end=end))
    rep = report(simulate(blocks, XY_TABLE, "ph-lookahead"), "uneven", "ph-lookahead", XY_TABLE)
    assert rep["contour_limit_met"]
    assert rep["contour_error_true_um"]["max"] <= limit_um(XY_TABLE)
    assert rep["motion_time_s"] < 1.2  # a stop at the turn, then the feed again (was 3.4 s)


# A cusp next to a weight of 0.01 (weights within the interpreter's factor 1000): the curve runs
# out to X7 and back, and where it turns back its feed limit is 5e-21 mm/s at one grid sample.
CUSP_NEXT_TO_LIGHT_WEIGHT = """F1000
G5.2 P0.500000 L3
X7.000000 Y0.000000 P1
X7.000000 Y0.000000 P0.010000
X0.007000 Y0.007000 P1
G5.3
"""


def test_a_lone_spike_of_the_feed_limit_is_a_stop(tmp_path: Path) -> None:
    """It was planned as a creep of 1.4e7 s toward and away from that sample (the quintics
    cannot follow the straight rise the grid draws from it) and refused by the planner's 3600 s
    guard, mid-program, after `check` had passed the program. Now the plan rests there."""
    blocks = blocks_of(tmp_path, CUSP_NEXT_TO_LIGHT_WEIGHT)
    rep = report(simulate(blocks, XY_TABLE, "ph-lookahead"), "cusp", "ph-lookahead", XY_TABLE)
    assert rep["contour_limit_met"]
    assert rep["contour_error_true_um"]["max"] <= limit_um(XY_TABLE)
    assert rep["motion_time_s"] < 14.0 / 16.0 + 0.2  # 14 mm at F1000, and the stop


def test_spikes_are_lone_samples_far_under_the_programmed_feed() -> None:
    curve = _curve(2.0)
    piece = make_piece(PieceKind.NURBS, curve, 0.0, 2.0, 0.0, 16.0, 3)
    path = ToolPath((piece,))
    s = np.linspace(0.0, piece.length_mm, 11)
    vlim = np.full(11, 16.0)
    assert path_plan.spike_stops_mm(path, s, vlim, 58.0) == ()
    vlim[4] = 0.001  # under 1e-3 of the feed 16: a spike
    vlim[7] = 0.05  # 3e-3 of it: a slow corner, passed
    assert path_plan.spike_stops_mm(path, s, vlim, 58.0) == (float(s[4]),)
    vlim[5] = 0.001  # two low samples in a row are a stretch, not a spike
    assert path_plan.spike_stops_mm(path, s, vlim, 58.0) == ()
    slow = make_piece(PieceKind.NURBS, curve, 0.0, 2.0, 0.0, 0.0167, 3)  # F1: all of it slow
    assert path_plan.spike_stops_mm(ToolPath((slow,)), s, np.full(11, 0.0167), 58.0) == ()


# Found by 120 random NURBS with knot spans up to 1e4 apart and weights down to 0.01: the
# tool was 44 um from the path (limit 30), its first knot span 8241 times the next one.
SEVEN_SPANS = """G21 G90 G64
G1 X0 Y0 F1000
G6.2 P3 X0.0000 Y0.0000 R1.0000 K0.000000
X-4.6454 Y2.9149 R1.0000 K0.000000
X-9.2618 Y1.7098 R1.0000 K0.000000
X-9.8384 Y2.3694 R1.0000 K8240.965619
X-9.1226 Y3.4049 R1.0000 K8241.965619
X-13.8774 Y1.6903 R1.0000 K8244.843733
X-11.4965 Y0.8624 R1.0000 K8247.028487
X-8.2334 Y1.2982 R1.0000 K8253.478854
K8254.646771
K8254.646771
K8254.646771
M2
"""


def _random_uneven(seed: int) -> str:
    """A quadratic or cubic NURBS with knot spans up to 1e4 apart and, half the time, weights
    down to 0.01, as in the hunt that found SEVEN_SPANS."""
    rng = np.random.default_rng(seed)
    order = int(rng.integers(3, 5))
    n = int(rng.integers(order, order + 6))
    pts = np.clip(np.cumsum(rng.uniform(-5.0, 5.0, (n, 2)), axis=0), -100.0, 100.0)
    pts[0] = 0.0
    w = np.exp(rng.uniform(np.log(0.01), 0.0, n)) if rng.random() < 0.5 else np.ones(n)
    spans = np.exp(rng.uniform(0.0, np.log(1e4), n - order + 1))
    spans = 1.0 + (spans / spans.min() - 1.0) * min(1.0, 9998.0 / (spans.max() / spans.min()))
    knots = np.r_[[0.0] * order, np.cumsum(spans)[:-1], [spans.sum()] * order]
    rows = [f"G6.2 P{order} X0 Y0 R{w[0]:.4f} K{knots[0]:.6f}"]
    rows += [f"X{x:.4f} Y{y:.4f} R{r:.4f} K{k:.6f}"
             for (x, y), r, k in zip(pts[1:], w[1:], knots[1:n], strict=True)]
    rows += [f"K{k:.6f}" for k in knots[n:]]
    return "\n".join(["G21 G90 G64", "G1 X0 Y0 F3500", *rows, "M2", ""])


@pytest.mark.parametrize("text", [SEVEN_SPANS, *(_random_uneven(seed) for seed in range(8))],
                         ids=["seven_spans", *(f"random{seed}" for seed in range(8))])
def test_uneven_nurbs_stay_within_the_contour_limit(tmp_path: Path, text: str) -> None:
    blocks = blocks_of(tmp_path, text)
    rep = report(simulate(blocks, XY_TABLE, "ph-lookahead"), "uneven", "ph-lookahead", XY_TABLE)
    assert rep["contour_limit_met"]
    assert rep["max_feed_mm_s"] <= 58.34
