"""Random valid programs through the generator: never a crash, never a limit exceeded."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from controller.config import load_config
from controller.generator.plan import generate_reference
from controller.interpreter.program import read_program
from controller.runtime.simulation import report, simulate

CFG = load_config()
IP = CFG.interpolator

coord = st.floats(-60.0, 60.0, allow_nan=False).map(lambda v: round(v, 3))
move = st.one_of(
    st.tuples(st.just("G1"), coord, coord),
    st.tuples(st.just("G0"), coord, coord),
    st.tuples(st.sampled_from(["G2", "G3"]), coord, coord),
)
mode = st.sampled_from(["G64", "G64 P0.01", "G64 P0.2", "G61"])


def _program(moves: list[tuple[str, float, float]], path_mode: str, feed: int) -> str:
    lines = ["G17 G21 G90", f"F{feed}", path_mode]
    x = y = 0.0
    for code, nx, ny in moves:
        if math.hypot(nx - x, ny - y) < 0.01:
            continue
        if code in ("G2", "G3"):
            # a semicircle-or-less arc: centre at the chord's midpoint, pushed sideways
            cx, cy = 0.5 * (x + nx), 0.5 * (y + ny)
            lines.append(f"{code} X{nx:.3f} Y{ny:.3f} I{cx - x:.4f} J{cy - y:.4f}")
        else:
            lines.append(f"{code} X{nx:.3f} Y{ny:.3f}")
        x, y = nx, ny
    return "\n".join([*lines, "M2", ""])


@example(moves=[("G1", 0.0, -38.0), ("G3", 49.0, 0.0), ("G3", 50.0, 0.0)],
         path_mode="G64", feed=866)  # the chord measure reads 2450.33 mm/s^2 at Amax 2450
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(st.lists(move, min_size=1, max_size=12), mode, st.integers(300, 3500))
def test_random_programs_plan_within_the_limits(tmp_path: Path, moves: list, path_mode: str,
                                                feed: int) -> None:
    prog = tmp_path / "random.nc"
    prog.write_text(_program(moves, path_mode, feed), encoding="utf-8")
    blocks = list(read_program(str(prog), CFG))
    chunks = list(generate_reference(iter(blocks), CFG))
    if not chunks:
        return
    ref = np.vstack([c.pos_mm for c in chunks])
    last = [b for b in blocks if hasattr(b, "end")][-1]
    assert np.array_equal(ref[-1], np.array(last.end[:2]))
    traj = simulate(iter(blocks), CFG, "ph-lookahead")
    # The second plan of the same program in one process is the same plan (per-run caches and
    # the planner's memo must not leak state from one plan into the next).
    assert np.array_equal(traj.ref_mm, ref)
    r = report(traj, str(prog), "ph-lookahead", CFG)
    # The planned feed changes by at most Amax per period: what the planner guarantees ...
    amax = IP.max_accel_mm_s2
    assert np.abs(np.diff(traj.feed_mm_s)).max() / CFG.sample_period_s <= amax * (1 + 1e-6)
    # ... and the sampled path agrees. The report measures from chord lengths, and a chord is
    # shorter than its arc by (k v T)^2 / 24: where the curvature k changes under a feed
    # ramp (a 0.5 mm arc after a PH corner at 12 mm/s) that reads some 0.3 mm/s^2 over Amax.
    assert r["max_tangential_accel_mm_s2"] <= amax * 1.001
    assert r["max_feed_mm_s"] <= IP.rapid_feed_mm_s * (1 + 1e-9)
    assert r["contour_limit_met"]
    assert r["contour_error_um"]["max"] <= IP.contour_error_limit_mm * 1000
