"""Every program in nc_programs/ simulates to the recorded figures and trajectories, bit for bit.

Bit for bit holds on the platform the figures were recorded on (numpy version and CPU features);
elsewhere numpy may choose other SIMD kernels, so there the figures must agree to 1e-9 relative
and the trajectory hashes are not compared."""

from __future__ import annotations

import json
import math

import pytest
from simulate_golden import GOLDEN, figures, platform, programs


def _golden() -> dict:
    return json.loads(GOLDEN.read_text(encoding="utf-8"))


def _close(a: object, b: object, path: str = "") -> list[str]:
    """Where two reports differ beyond round-off (hashes skipped)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a if k != "trajectory_sha256" for d in _close(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, float) and isinstance(b, float):
        return [] if math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) else [f"{path}: {a} != {b}"]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def test_every_program_has_golden_figures() -> None:
    assert sorted(_golden()["programs"]) == [p.name for p in programs()]


@pytest.mark.parametrize("program", programs(), ids=lambda p: p.name)
def test_simulate_figures_unchanged(program) -> None:
    golden = _golden()
    recorded = golden["programs"][program.name]
    now = figures(program)
    if golden["platform"] == platform():
        assert now == recorded
    else:
        assert _close(now, recorded) == []


def test_close_finds_a_changed_figure() -> None:
    a = {"x": {"max": 1.0, "trajectory_sha256": "a"}, "n": 3}
    assert _close(a, {"x": {"max": 1.0, "trajectory_sha256": "b"}, "n": 3}) == []
    assert _close(a, {"x": {"max": 1.0 + 1e-6, "trajectory_sha256": "a"}, "n": 3}) != []
    assert _close(a, {"x": {"max": 1.0, "trajectory_sha256": "a"}, "n": 4}) != []
