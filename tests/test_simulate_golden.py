"""Every program in nc_programs/ simulates to the recorded figures and trajectories.

Bit for bit on the platform the figures were recorded on (numpy and scipy versions, CPU
features and model, OpenBLAS kernel, libc: see simulate_golden.platform). Elsewhere each figure
must lie within the spread recorded under round-off-sized perturbations of the machine, widened
by 1e-6 relative (simulate_golden.compare); the trajectory hashes are not compared there."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import pytest
from simulate_golden import (
    CONFIG_NAME,
    GOLDEN,
    compare,
    figures,
    perturbed,
    platform,
    programs,
)

from controller.config import load_config


def _golden() -> dict:
    return json.loads(GOLDEN.read_text(encoding="utf-8"))


def test_every_program_has_golden_figures() -> None:
    golden = _golden()
    names = [p.name for p in programs()]
    assert sorted(golden["programs"]) == names and sorted(golden["spread"]) == names


@pytest.mark.parametrize("program", programs(), ids=lambda p: p.name)
def test_simulate_figures_unchanged(program: Path) -> None:
    golden = _golden()
    recorded = golden["programs"][program.name]
    now = figures(program)
    if golden["platform"] == platform():
        assert now == recorded
    else:
        assert compare(now, recorded, golden["spread"][program.name]) == []


# -- the comparison used on other platforms -----------------------------------------------
REPORT = {"ph-lookahead": {"motion_time_s": 1.11, "samples": 1110, "limit_met": True,
                           "error": {"max": 27.1076043473, "at": [0.5, 2]},
                           "trajectory_sha256": "a"}}


def _with(path: tuple, value: object) -> dict:
    out = copy.deepcopy(REPORT)
    node = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out


def test_round_off_passes_and_the_hash_is_not_compared() -> None:
    now = _with(("ph-lookahead", "error", "max"), 27.1076043373)  # two CPUs, as seen
    now["ph-lookahead"]["trajectory_sha256"] = "b"
    assert compare(now, REPORT, {}) == []


@pytest.mark.parametrize("path, value", [
    (("ph-lookahead", "motion_time_s"), 1.111),  # one sample more
    (("ph-lookahead", "samples"), 1111),
    (("ph-lookahead", "error", "max"), 27.11),
    (("ph-lookahead", "limit_met"), False),
    (("ph-lookahead", "error", "at", 1), 3),
])
def test_a_real_change_fails(path: tuple, value: object) -> None:
    assert compare(_with(path, value), REPORT, {}) != []


def test_a_missing_or_new_figure_fails() -> None:
    now = copy.deepcopy(REPORT)
    del now["ph-lookahead"]["samples"]
    assert compare(now, REPORT, {}) != []
    assert compare(_with(("ph-lookahead", "new"), 1), REPORT, {}) != []


def test_a_decision_round_off_flipped_at_recording_passes_within_its_spread() -> None:
    spread = {"/ph-lookahead/motion_time_s": [1.10, 1.13], "/ph-lookahead/samples": [1100, 1130],
              "/ph-lookahead/limit_met": ["false", "true"]}
    flipped = _with(("ph-lookahead", "motion_time_s"), 1.125)
    flipped["ph-lookahead"]["samples"] = 1125
    flipped["ph-lookahead"]["limit_met"] = False
    assert compare(flipped, REPORT, spread) == []
    assert compare(_with(("ph-lookahead", "motion_time_s"), 1.2), REPORT, spread) != []


def test_a_new_round_off_passes_and_a_real_change_fails_on_a_real_plan() -> None:
    """The airfoil planned under a perturbation not among those recorded passes the
    comparison; Amax 0.1 % lower (a real change) fails it."""
    golden = _golden()
    program = next(p for p in programs() if p.name == "naca2415.nc")
    recorded, spread = golden["programs"][program.name], golden["spread"][program.name]
    base = load_config(CONFIG_NAME)
    assert compare(figures(program, perturbed(base, 7 * 2.0**-50)), recorded, spread) == []
    slower = dataclasses.replace(base, interpolator=dataclasses.replace(
        base.interpolator, max_accel_mm_s2=base.interpolator.max_accel_mm_s2 * 0.999))
    assert compare(figures(program, slower), recorded, spread) != []


def test_figures_recorded_on_another_cpu_pass() -> None:
    """Recorded on a CPU with the same features and libraries, they differ by 1e-10 relative,
    and the nurbs-lookahead baseline plans the looped airfoil in 2.251 s there (a flip that
    the perturbations here show as 2.19-2.93 s)."""
    golden = _golden()
    other = json.loads((GOLDEN.parent / "simulate_figures_other_cpu.json").read_text("utf-8"))
    for name, recorded in golden["programs"].items():
        theirs = other["programs"][name]
        mine = {a: {k: v for k, v in r.items() if not k.startswith("trajectory_")}
                for a, r in recorded.items()}
        assert compare(theirs, mine, golden["spread"][name]) == [], name
