"""Servo filters and reference paths that the servo tests share."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from controller.config import ServoParams
from controller.servo.model import DiscreteServo

TABLE_II = ServoParams(
    a0=1.938e9, a1=3.538e7, a2=2.135e5, a3=698.4, a4=1.0, b0=1.938e9, b1=3.476e7, b2=1.471e5
)  # config/xy_table.yaml's X
# A 5th-order filter next to the 4th-order ones (stacked states are padded to it).
FIFTH = DiscreteServo(
    b=np.array([0.0, 2e-4, -1e-4, 5e-5, 0.0, 1e-5]),
    a=np.poly([0.5, 0.6, 0.7, 0.8, 0.9]),
    sample_period_s=0.001,
)


def draw_polyline(draw: st.DrawFn, max_points: int, max_scale_mm: float) -> tuple[
        np.random.Generator, np.ndarray]:
    """A random generator and a reference polyline: a curve folding back on itself, a random
    walk, or one with repeated points (zero-length segments)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(2, max_points))
    shape = draw(st.sampled_from(["fold", "walk", "repeats"]))
    if shape == "fold":
        t = np.linspace(0.0, draw(st.floats(1.0, 30.0)), n)
        ref = np.column_stack((np.cos(t), np.sin(2.0 * t))) * draw(st.floats(0.05, max_scale_mm))
    elif shape == "walk":
        ref = np.cumsum(rng.standard_normal((n, 2)) * draw(st.floats(1e-4, 0.5)), axis=0)
    else:
        ref = np.repeat(rng.standard_normal((n // 3 + 1, 2)), 3, axis=0)[:n]
    return rng, ref
