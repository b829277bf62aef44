"""`cncctl simulate` streams: the same numbers as the whole arrays, in bounded memory."""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from long_helpers import walk

from controller.config import load_config
from controller.generator.plan import plan_program
from controller.interpreter.program import read_program
from controller.runtime.simulate_figures import Figures, Moments
from controller.runtime.simulate_stream import ServoStream
from controller.runtime.simulation import simulate, tangent_angles
from controller.servo.model import contour_error_mm, tracking_error_mm
from controller.servo.prediction import SETTLE_S, axis_servos
from controller.servo.true_distance import distance_from_reference_mm

REPO = Path(__file__).resolve().parents[2]
XY = load_config(None)
MILL = load_config("xyz_mill")
ARRAYS = ("t_s", "ref_mm", "act_mm", "feed_mm_s", "line", "ex_mm", "ey_mm", "contour_mm",
          "contouring", "true_mm")


def whole_arrays(steps: list, config) -> dict[str, np.ndarray]:
    """The simulation as it was computed before it streamed: every array at once."""
    ref = np.vstack([s.chunk.pos_mm for s in steps])
    T = config.sample_period_s  # noqa: N806
    settle = int(round(SETTLE_S / T))
    pos = np.vstack([np.zeros((1, ref.shape[1])), ref, np.repeat(ref[-1:], settle, axis=0)])
    v = np.diff(pos, axis=0) / T
    servos = axis_servos(config)
    ex, ey = tracking_error_mm(servos[0], v[:, 0]), tracking_error_mm(servos[1], v[:, 1])
    phi = tangent_angles(pos[1:, :2])
    k = 0
    for s in steps:
        if s.phi_rad is not None:
            phi[k:k + len(s.chunk)] = s.phi_rad
        k += len(s.chunk)
    phi[k:] = phi[k - 1]
    n = len(ref)
    act = ref.copy()
    act[:, 0] -= ex[:n]
    act[:, 1] -= ey[:n]
    rapid = np.concatenate([np.full(len(s.chunk), s.rapid) for s in steps])
    held = pos[1:, :2]
    return {"t_s": np.arange(1, n + 1) * T, "ref_mm": ref, "act_mm": act,
            "feed_mm_s": np.concatenate([s.chunk.feed_mm_s for s in steps]),
            "line": np.concatenate([s.chunk.line for s in steps]), "ex_mm": ex, "ey_mm": ey,
            "contour_mm": contour_error_mm(ex, ey, phi),
            "contouring": ~np.r_[rapid, np.full(settle, rapid[-1])],
            "true_mm": distance_from_reference_mm(held, held - np.column_stack([ex, ey]))}


MILL_PROGRAM = """G21 G90 G64 F2400
G0 X0 Y0 Z5
G1 Z-1 F600
G1 X20 Y0 F2400
G3 X30 Y10 I0 J10
G1 X30 Y25
G4 P0.1
G1 X5 Y25
G0 Z5
G0 X0 Y0
M2
"""


@pytest.mark.parametrize("name", ["naca2415.nc", "g64_corners.nc", "walk", "mill"])
def test_streamed_arrays_are_the_whole_arrays_bit_for_bit(name: str, tmp_path: Path) -> None:
    config = MILL if name == "mill" else XY
    if name == "walk":  # two look-ahead windows, continued mid-cruise
        program = str(walk(tmp_path, 650))
    elif name == "mill":
        (tmp_path / "mill.nc").write_text(MILL_PROGRAM, encoding="utf-8")
        program = str(tmp_path / "mill.nc")
    else:
        program = str(REPO / "nc_programs" / name)
    steps = list(plan_program(read_program(program, config), config))
    expected = whole_arrays(steps, config)
    traj = simulate(read_program(program, config), config, "ph-lookahead")
    for field in ARRAYS:
        got = getattr(traj, field)
        assert got.dtype == expected[field].dtype and np.array_equal(got, expected[field]), field


def test_any_split_of_the_reference_gives_the_same_samples() -> None:
    """Pushed in chunks of any size, the stream finishes the same samples to the last bit."""
    steps = list(plan_program(read_program(str(REPO / "nc_programs/naca2415.nc"), XY), XY))
    ref = np.vstack([s.chunk.pos_mm for s in steps])
    feed = np.concatenate([s.chunk.feed_mm_s for s in steps])
    line = np.concatenate([s.chunk.line for s in steps])
    rng = np.random.default_rng(3)
    results = []
    for sizes in ([len(ref)], [1, 2, 3, 255, 256, 257], list(rng.integers(1, 90, 60))):
        stream, out, k = ServoStream(XY), [], 0
        while k < len(ref):
            m = int(sizes[len(out) % len(sizes)]) if k else int(sizes[0])
            out += list(stream.push(ref[k:k + m], feed[k:k + m], line[k:k + m], False, None))
            k += m
        out += list(stream.finish())
        results.append({f: np.concatenate([getattr(b, f) for b in out])
                        for f in ("ex_mm", "ey_mm", "contour_mm", "true_mm")})
    for other in results[1:]:
        for field, value in other.items():
            assert np.array_equal(value, results[0][field]), field


def test_moments_are_numpys_until_the_limit_then_agree_to_round_off() -> None:
    rng = np.random.default_rng(5)
    parts = [np.abs(rng.normal(size=int(n))) * 30.0 for n in rng.integers(1, 3000, 40)]
    whole = np.concatenate(parts)
    exact, folded = Moments(), Moments(exact_limit=1000)
    for p in parts:
        exact.add(p)
        folded.add(p)
    expected = {"max": float(whole.max()), "rms": float(np.sqrt(np.mean(whole * whole))),
                "mean": float(whole.mean())}
    assert exact.stats() == expected
    for key, value in folded.stats().items():
        assert value == pytest.approx(expected[key], rel=1e-13)


def test_stream_and_figures_keep_bounded_memory_on_a_long_reference() -> None:
    """Half an hour of samples pushed through the stream and the figures: only the kept window
    and the first exact_limit values are in memory, not the 1.8 million samples (about 650 MB
    as the whole arrays of the simulation were)."""
    stream, figures = ServoStream(XY), Figures(2, XY.sample_period_s, exact_limit=1 << 14)
    t = np.arange(4000) * 1e-3
    tracemalloc.start()
    try:
        for k in range(450):
            phase = (t + 4.0 * k) * 0.5
            pos = np.column_stack([40.0 * np.cos(phase) - 40.0, 40.0 * np.sin(phase)])
            for b in stream.push(pos, np.full(len(t), 20.0), np.full(len(t), k, np.int32),
                                 False, None):
                figures.add(b)
        for b in stream.finish():
            figures.add(b)
        peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
    assert figures.n_ref == 1_800_000
    assert peak_mb < 25.0
    r = figures.report("circle", "ph-lookahead", 30.0, 0.0)
    assert r["max_feed_mm_s"] == pytest.approx(20.0, rel=1e-3)


def test_simulate_of_a_long_walk_stays_small(tmp_path: Path) -> None:
    """The whole `cncctl simulate` process on 6000 G1 lines (80 s of motion, 80,000 samples,
    30 MB of samples kept before it streamed): its peak RSS."""
    program = walk(tmp_path, 6000)
    # VmHWM, not ru_maxrss: a child's ru_maxrss starts from its parent's (pytest's) at fork.
    code = ("import sys\nfrom controller.operator.cli import main\n"
            f"code = main(['simulate', {str(program)!r}, '--json'])\n"
            "print(next(t for t in open('/proc/self/status') if t.startswith('VmHWM')))\n"
            "sys.exit(code)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, cwd=REPO)
    assert out.returncode == 0, out.stderr
    peak_mb = int(out.stdout.strip().splitlines()[-1].split()[1]) / 1024
    assert peak_mb < 150.0
