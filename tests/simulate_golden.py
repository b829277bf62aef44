"""Golden figures of `cncctl simulate --compare --json` on every program in nc_programs/.

The figures of each algorithm's report (all but the wall-clock planning time) and a SHA-256 of
each algorithm's whole trajectory arrays, so that a change meant to move code and not behaviour
(issue 14) is checked bit for bit. `python tests/simulate_golden.py --write` records them."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import sys
from pathlib import Path

import numpy as np
import scipy

from controller.config import load_config
from controller.generator.plan import Algorithm
from controller.interpreter.program import read_program
from controller.operator.cli import main
from controller.runtime.simulation import simulate

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "tests/data/simulate_golden.json"
WALL_CLOCK_KEYS = ("planning_cpu_s",)


def programs() -> list[Path]:
    return sorted((REPO / "nc_programs").glob("*.nc"))


def _simulate_json(program: Path) -> dict:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["simulate", str(program), "--compare", "--json", "--config", "xy_table_paper"])
    assert code == 0, f"cncctl simulate {program.name} exited {code}"
    return json.loads(out.getvalue())


def _trajectory_sha256(program: Path, algorithm: str) -> str:
    config = load_config("xy_table_paper")
    traj = simulate(read_program(str(program), config), config, algorithm)
    digest = hashlib.sha256()
    for name in ("t_s", "ref_mm", "act_mm", "feed_mm_s", "line", "ex_mm", "ey_mm", "contour_mm",
                 "contouring"):
        digest.update(np.ascontiguousarray(getattr(traj, name)).tobytes())
    return digest.hexdigest()


def figures(program: Path) -> dict:
    """What must not change: every reported figure and every trajectory, per algorithm."""
    results = {}
    for r in _simulate_json(program)["results"]:
        kept = {k: v for k, v in r.items() if k not in WALL_CLOCK_KEYS and k != "program"}
        kept["trajectory_sha256"] = _trajectory_sha256(program, r["algorithm"])
        results[r["algorithm"]] = kept
    assert sorted(results) == sorted(a.value for a in Algorithm)
    return results


def platform() -> dict:
    """What the bits depend on besides our code: numpy picks its SIMD kernels (SVML on AVX-512)
    by CPU feature at run time, so another CPU or library version may round differently."""
    from numpy._core._multiarray_umath import __cpu_features__

    return {"numpy": np.__version__, "scipy": scipy.__version__,
            "cpu_features": sorted(k for k, on in __cpu_features__.items() if on)}


def all_figures() -> dict:
    return {"platform": platform(), "programs": {p.name: figures(p) for p in programs()}}


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/simulate_golden.py --write")
    GOLDEN.write_text(json.dumps(all_figures(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"wrote {GOLDEN}")
