"""Every program `check` accepts also plans and runs within the contour limit, or `check`
refuses it: NURBS mutated as a fuzzer does (repeated points, tiny weights, near-cusps)."""

from __future__ import annotations

import json
import random
import subprocess
from pathlib import Path

import pytest
from daemon_helpers import CNCCTL

BASE = [(10.0, 30.0, 1.0), (40.0, 40.0, 2.0), (60.0, -10.0, 1.0), (90.0, 20.0, 0.5),
        (100.0, 0.0, 1.0)]


def _program(points: list[tuple[float, float, float]], order: int) -> str:
    lines = ["G17 G21 G90", "G0 X0 Y0", "F2000", f"G5.2 P1 L{order}"]
    lines += [f"    X{x:.6f} Y{y:.6f} P{w:g}" for x, y, w in points]
    return "\n".join(lines + ["G5.3", "G1 X100 Y-20", "M2"]) + "\n"


def _mutate(rng: random.Random, points: list) -> list:
    points = list(points)
    kind = rng.choice(["repeat", "repeat2", "weight", "cusp", "start"])
    i = rng.randrange(len(points))
    if kind == "repeat":
        points.insert(i, points[i])
    elif kind == "repeat2":
        points[i:i] = [points[i], points[i]]
    elif kind == "weight":
        points[i] = (*points[i][:2], rng.choice([0.01, 0.05, 50.0, 100.0]))
    elif kind == "cusp":  # next to its neighbour, 1 um down to 1e-6 mm away
        j = min(i + 1, len(points) - 1)
        points[i] = (points[j][0] + rng.choice([1e-3, 1e-4, 1e-6]), points[j][1], points[i][2])
    else:
        points.insert(0, (rng.choice([0.0, 1e-6, 1e-3]), 0.0, points[0][2]))
    return points


def _cases() -> list[tuple[int, str]]:
    rng = random.Random(2026)
    cases = []
    while len(cases) < 14:
        points = BASE
        for _ in range(rng.randint(1, 3)):
            points = _mutate(rng, points)
        order = rng.choice([3, 4, 4, 5])
        if len(points) >= order:
            cases.append((len(cases), _program(points, order)))
    # a found one: a control point 1e-6 mm from the last made a hook planned as 6456 s
    cases.append((len(cases), _program(BASE[:3] + [(100.000001, 0.0, 0.5), BASE[4]], 3)))
    return cases


@pytest.mark.parametrize("case", _cases(), ids=lambda c: f"mutant{c[0]}")
def test_check_accepts_only_what_simulate_plans_within_the_limit(tmp_path: Path,
                                                                 case: tuple[int, str]) -> None:
    path = tmp_path / "mutant.nc"
    path.write_text(case[1])
    check = subprocess.run([*CNCCTL, "check", str(path)], capture_output=True, text=True,
                           timeout=120)
    if check.returncode != 0:
        assert check.returncode == 2 and f"{path}:" in check.stderr and "error:" in \
            check.stderr, check.stderr
        return
    sim = subprocess.run([*CNCCTL, "simulate", str(path), "--json"], capture_output=True,
                         text=True, timeout=300)
    assert sim.returncode == 0, (case[1], sim.stderr[-500:])
    report = json.loads(sim.stdout)
    assert report["contour_limit_met"], report["contour_error_true_um"]
