"""`cncctl inspect --plot` draws every block: lines, arcs and NURBS cover the program's extent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from controller.config import load_config  # noqa: E402
from controller.interpreter.program import read_program  # noqa: E402
from controller.operator.check_cmd import check_program  # noqa: E402
from controller.operator.inspect_plot import draw_report  # noqa: E402
from controller.operator.inspect_report import inspect_blocks  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
MIXED = """G17 G21 G90
F1200
G0 X-20 Y-10
G1 X0 Y0
G3 X10 Y10 I0 J10
G5.2 P1 L4
X20 Y30 P1
X30 Y-5 P1
X40 Y12 P1
G5.3
G1 X45 Y12
M2
"""


def _drawn_extent(path: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """(min XY, max XY, lines drawn) of the path axes of the inspect figure."""
    import matplotlib.pyplot as plt

    config = load_config("xy_table")
    fig = draw_report(inspect_blocks(read_program(str(path), config), config))
    try:
        ax_path = fig.axes[0]
        xy = np.vstack([line.get_xydata() for line in ax_path.get_lines()])
        return xy.min(axis=0), xy.max(axis=0), len(ax_path.get_lines())
    finally:
        plt.close(fig)


@pytest.mark.parametrize("name", ["arcs.nc", "naca2415.nc", "nurbs_g52.nc", "mixed.nc"])
def test_the_plot_covers_the_program(tmp_path: Path, name: str) -> None:
    path = REPO / "nc_programs" / name
    if name == "mixed.nc":
        path = tmp_path / name
        path.write_text(MIXED)
    config = load_config("xy_table")
    extents = check_program(str(path), config).extents_mm
    lo, hi, count = _drawn_extent(path)
    assert count > 0
    assert lo == pytest.approx([extents["x"][0], extents["y"][0]], abs=0.05)
    assert hi == pytest.approx([extents["x"][1], extents["y"][1]], abs=0.05)
