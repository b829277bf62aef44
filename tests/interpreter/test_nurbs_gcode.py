"""G5.2/G6.2 NURBS blocks: LinuxCNC and Fanuc forms, knot vectors, and the check's sampler."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from geomdl import NURBS
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of

from controller.blocks import NurbsBlock
from controller.interpreter.extent import _sample_spans, nurbs_length_and_box
from controller.interpreter.program import read_program
from controller.operator.check_cmd import check_program

REPO = Path(__file__).resolve().parents[2]


def test_linuxcnc_g5_2_example(tmp_path: Path) -> None:
    text = "G0 X0 Y0\nF100\nG5.2 P1 L3\nX0 Y1 P1\nX2 Y2 P1\nX2 Y0 P1\nX0 Y0 P2\nG5.3\n"
    (b,) = blocks_of(tmp_path, text)
    assert isinstance(b, NurbsBlock) and b.degree == 2
    np.testing.assert_array_equal(b.control_points, [[0, 0], [0, 1], [2, 2], [2, 0], [0, 0]])
    np.testing.assert_array_equal(b.weights, [1, 1, 1, 1, 2])
    np.testing.assert_array_equal(b.knots, [0, 0, 0, 1, 2, 3, 3, 3])
    assert (b.source.first_line, b.source.last_line) == (3, 8)
    assert b.feed_mm_s == pytest.approx(100 / 60)


def test_g5_2_first_line_with_a_point_keeps_the_current_position_first(tmp_path: Path) -> None:
    (b,) = blocks_of(tmp_path, "F100\nG0 X5 Y5\nG5.2 X6 Y7 P2 L4\nX7 Y5 P1\nX8 Y8 P1\nG5.3\n")[1:]
    np.testing.assert_array_equal(b.control_points[:2], [[5, 5], [6, 7]])
    np.testing.assert_array_equal(b.weights, [1, 2, 1, 1])
    assert b.degree == 3 and b.knots.size == 8


def test_position_after_nurbs_is_the_last_control_point(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "F100\nG5.2 L3\nX1 Y1 P1\nX2 Y0 P1\nG5.3\nG1 X3\n")
    assert b[1].start == (2.0, 0.0, 0.0)


def test_g6_2_naca_benchmark() -> None:
    blocks = list(read_program(str(REPO / "nc_programs/naca2415.nc"), XY_TABLE))
    b = blocks[0]
    assert isinstance(b, NurbsBlock) and b.degree == 3
    assert b.control_points.shape == (40, 2) and b.knots.size == 44
    assert b.start == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(b.knots[:4], 0.0)
    np.testing.assert_array_equal(b.knots[-4:], 1.0)
    assert len(blocks) == 2  # the closing G1 to the last control point has zero length


def test_g6_2_fanuc_knot_lines_without_repeated_g(tmp_path: Path) -> None:
    text = ("F60\nG6.2 P3 X0 Y0 R1 K0 Q1\n X1 Y2 R2 K0\n X3 Y0 R1 K0\n X4 K1\nK2\nK2\nK2\n"
            "G1 X0 Y0\n")
    b = blocks_of(tmp_path, text)
    nurbs = b[0]
    np.testing.assert_array_equal(nurbs.control_points, [[0, 0], [1, 2], [3, 0], [4, 0]])
    np.testing.assert_array_equal(nurbs.weights, [1, 2, 1, 1])
    np.testing.assert_array_equal(nurbs.knots, [0, 0, 0, 1, 2, 2, 2])
    assert (nurbs.source.first_line, nurbs.source.last_line) == (2, 8)
    assert b[1].start == (4.0, 0.0, 0.0)


def test_g6_2_ends_at_end_of_file_and_keeps_z(tmp_path: Path) -> None:
    text = "G0 Z2\nF60\nG6.2 P2 X0 Y0 K0\nX1 Y1 K0\nG6.2 K1\nG6.2 K1\n"
    (b,) = blocks_of(tmp_path, text, XYZ_MILL)[1:]
    assert b.z_mm == 2.0 and b.degree == 1


def test_two_g6_2_blocks_in_a_row(tmp_path: Path) -> None:
    text = ("F60\nG6.2 P2 X0 Y0 K0\nX1 Y1 K0\nK1\nK1\n"
            "G6.2 P2 X1 Y1 K0\nX2 Y0 K0\nK1\nK1\n")
    b = blocks_of(tmp_path, text)
    assert len(b) == 2 and b[1].start == (1.0, 1.0, 0.0) and b[1].end == (2.0, 0.0, 0.0)


def _geomdl_point(b: NurbsBlock, u: float) -> np.ndarray:
    c = NURBS.Curve()
    c.degree = b.degree
    c.ctrlpts = b.control_points.tolist()
    c.weights = b.weights.tolist()
    t = b.knots
    c.knotvector = ((t - t[0]) / (t[-1] - t[0])).tolist()
    return np.array(c.evaluate_single((u - t[0]) / (t[-1] - t[0])))


@pytest.mark.parametrize("program", ["butterfly.nc", "naca2415.nc", "nurbs_g52.nc"])
def test_sampler_matches_geomdl(program: str) -> None:
    b = next(x for x in read_program(str(REPO / "nc_programs" / program), XY_TABLE)
             if isinstance(x, NurbsBlock))
    n = b.control_points.shape[0]
    spans = np.nonzero(b.knots[b.degree + 1 : n + 1] > b.knots[b.degree : n])[0] + b.degree
    pts = _sample_spans(b, spans, 4)
    k = np.repeat(spans, 4)
    u = b.knots[k] + np.tile(np.arange(4) / 4, spans.size) * (b.knots[k + 1] - b.knots[k])
    for i in range(0, u.size, max(1, u.size // 15)):
        np.testing.assert_allclose(pts[i], _geomdl_point(b, u[i]), atol=1e-9)


def test_benchmark_lengths_match_the_corpus_readme() -> None:
    for name, length_mm in (("naca2415.nc", 61.78), ("butterfly.nc", 382.86)):
        summary = check_program(str(REPO / "nc_programs" / name), XY_TABLE)
        assert summary.path_length_mm == pytest.approx(length_mm, abs=0.015)


def test_sampled_box_is_inside_the_control_point_box() -> None:
    b = next(read_program(str(REPO / "nc_programs/butterfly.nc"), XY_TABLE))
    _, (lo, hi) = nurbs_length_and_box(b)
    assert np.all(np.array(lo[:2]) >= b.control_points.min(axis=0) - 1e-12)
    assert np.all(np.array(hi[:2]) <= b.control_points.max(axis=0) + 1e-12)


def test_g62_starts_where_the_tool_is_within_a_pulse_or_two(tmp_path: Path) -> None:
    """A drive stands on whole pulses: a program that ended at Y0.00059 is at Y0.001 when it
    runs again, and its G6.2 X0 Y0 must still start there (from the exact position)."""
    text = "G1 X5 Y5.001 F600\nG6.2 P3 X5 Y5 R1 K0\nX6 Y6 R1 K0\nX7 Y5 R1 K0\nK1\nK1\nK1\n"
    nurbs = [b for b in blocks_of(tmp_path, text) if isinstance(b, NurbsBlock)]
    assert nurbs[0].control_points[0].tolist() == [5.0, 5.001]
    with pytest.raises(Exception, match="must be the current position"):
        blocks_of(tmp_path, text.replace("Y5.001", "Y5.003"))


def test_the_weight_check_is_linear_in_the_control_points() -> None:
    """A min and a max over every weight so far at each point: 20,000 points took 28 s. Four
    times the points now take about four times the CPU (quadratic: sixteen)."""
    import time

    from controller.blocks import PathControl
    from controller.interpreter.nurbs_blocks import NurbsCollector

    def cpu_s(n: int) -> float:
        collector = NurbsCollector("G5.2", 4, 0.0, 0.0, 1.0, 0.0, 10.0, PathControl(), "t.nc", 1)
        t0 = time.process_time()
        for i in range(1, n):
            collector.add_point(i * 0.001, 0.0, 1.0 + (i % 3), i)
        return time.process_time() - t0

    cpu_s(2000)  # warm
    small, large = min(cpu_s(6000) for _ in range(3)), min(cpu_s(24000) for _ in range(3))
    assert large < 8 * small, (small, large)
