"""Golden figures of `cncctl simulate --compare --json` on every program in nc_programs/.

For each algorithm: every figure of its report (all but the wall-clock planning time), a
SHA-256 of its whole trajectory arrays and the sum of |value| of each array. A change meant to
move code and not behaviour is checked bit for bit on the platform the figures were recorded
on. Elsewhere numpy, OpenBLAS and libm may pick other kernels and round differently, and round-
off can flip a planning decision (a contour error within 1e-12 of the limit, a cruise level
chosen by a tie); so `--write` also plans every program again under round-off-sized changes of
the machine (PERTURBATIONS) and records the spread of each figure (see compare()).
`python tests/simulate_golden.py --write` records them."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import platform as py_platform
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import scipy

from controller.config import MachineConfig, load_config
from controller.generator.plan import Algorithm
from controller.interpreter.program import read_program
from controller.operator.cli import main
from controller.runtime.simulation import simulate

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "tests/data/simulate_golden.json"
CONFIG_NAME = "xy_table_paper"
WALL_CLOCK_KEYS = ("planning_cpu_s",)
TRAJECTORY_ARRAYS = ("t_s", "ref_mm", "act_mm", "feed_mm_s", "line", "ex_mm", "ey_mm",
                     "contour_mm", "contouring")
# Relative changes of the servo coefficients and of Vmax and Amax, a few units in the last
# place: they change the round-off of every stage (geometry, feed, dynamics), as another SIMD
# kernel does, and nothing a machinist could measure.
PERTURBATIONS = tuple(sign * k * 2.0**-50 for k in (1, 2, 3, 5, 8, 13) for sign in (1, -1))
# A figure may differ from the recorded spread by this much (relative) on another platform:
# round-off moved figures by up to 5e-9 between two CPUs; a real change moves them by far more.
REL_TOL = 1e-6
ABS_TOL = 1e-9


# Mill programs (Z, tools, a probe) do not run on the paper's X-Y table: the tests of what
# they use check them (tests/operator/test_io_demo.py).
MILL_PROGRAMS = ("io_demo.nc",)


def programs() -> list[Path]:
    return sorted(p for p in (REPO / "nc_programs").glob("*.nc") if p.name not in MILL_PROGRAMS)


def _simulate_json(program: Path) -> dict:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["simulate", str(program), "--compare", "--json", "--config", CONFIG_NAME])
    assert code == 0, f"cncctl simulate {program.name} exited {code}"
    return json.loads(out.getvalue())


def _reports(program: Path, config: MachineConfig) -> list[dict]:
    """What `simulate --compare --json` reports, for a config that is no file."""
    from controller.operator.simulate_cmd import _one

    return [json.loads(json.dumps(_one(str(program), config, a.value))) for a in Algorithm]


def _trajectory(program: Path, algorithm: str, config: MachineConfig) -> dict:
    traj = simulate(read_program(str(program), config), config, algorithm)
    digest = hashlib.sha256()
    sums = {}
    for name in TRAJECTORY_ARRAYS:
        values = np.ascontiguousarray(getattr(traj, name))
        digest.update(values.tobytes())
        sums[name] = float(np.abs(values.astype(np.float64)).sum())
    return {"trajectory_sha256": digest.hexdigest(), "trajectory_abs_sums": sums}


def figures(program: Path, config: MachineConfig | None = None) -> dict:
    """What must not change: every reported figure and every trajectory, per algorithm (the
    shipped paper config through the command line; another config through the same code)."""
    reports = (_simulate_json(program)["results"] if config is None
               else _reports(program, config))
    config = config or load_config(CONFIG_NAME)
    results = {}
    for r in reports:
        kept = {k: v for k, v in r.items() if k not in WALL_CLOCK_KEYS and k != "program"}
        kept |= _trajectory(program, r["algorithm"], config)
        results[r["algorithm"]] = kept
    assert sorted(results) == sorted(a.value for a in Algorithm)
    return results


def perturbed(config: MachineConfig, rel: float) -> MachineConfig:
    """The machine with its servo coefficients, Vmax and Amax scaled by 1 + rel."""
    axes = tuple(dataclasses.replace(a, servo=dataclasses.replace(
        a.servo, **{f.name: getattr(a.servo, f.name) * (1 + rel)
                    for f in dataclasses.fields(a.servo)})) for a in config.axes)
    ip = config.interpolator
    return dataclasses.replace(config, axes=axes, interpolator=dataclasses.replace(
        ip, max_feed_mm_s=ip.max_feed_mm_s * (1 + rel),
        max_accel_mm_s2=ip.max_accel_mm_s2 * (1 + rel)))


# -- the spread of each figure ------------------------------------------------------------
def _leaves(tree: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(tree, dict):
        for key in sorted(tree):
            yield from _leaves(tree[key], f"{path}/{key}")
    elif isinstance(tree, list):
        for i, item in enumerate(tree):
            yield from _leaves(item, f"{path}/{i}")
    else:
        yield path, tree


def spread(runs: list[dict]) -> dict[str, list]:
    """For each leaf where the runs differ: [min, max] for numbers, the values seen else."""
    out: dict[str, list] = {}
    seen: dict[str, list] = {}
    for run in runs:
        for path, value in _leaves(run):
            if not path.endswith("trajectory_sha256"):
                seen.setdefault(path, []).append(value)
    for path, values in seen.items():
        if len({json.dumps(v) for v in values}) == 1 and len(values) == len(runs):
            continue
        numbers = [v for v in values if _is_number(v)]
        out[path] = ([min(numbers), max(numbers)] if len(numbers) == len(values)
                     else sorted({json.dumps(v) for v in values}))
    return out


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def compare(now: dict, recorded: dict, spread_of: dict[str, list]) -> list[str]:
    """Where `now` differs from the recording beyond round-off. A number must lie within the
    spread the perturbed plans showed (the recorded value alone where they agreed), widened
    by REL_TOL or by the spread's own width; anything else must be a value recorded or seen
    under perturbation; trajectory hashes are not compared. A decision that round-off
    flipped at recording (a dynamics round more, a millisecond of motion) is accepted; one
    that no perturbation flipped, or a figure moved by more than REL_TOL, is a real change."""
    ours, theirs = dict(_leaves(now)), dict(_leaves(recorded))
    diffs = [f"{p}: only {'now' if p in ours else 'recorded'}"
             for p in sorted(set(ours) ^ set(theirs))
             if not p.split("/")[-2].isdigit() and p not in spread_of]
    for path in sorted(set(ours) & set(theirs)):
        if path.endswith("trajectory_sha256"):
            continue
        value, want = ours[path], theirs[path]
        allowed = spread_of.get(path)
        if _is_number(value) and _is_number(want):
            lo, hi = (min(want, allowed[0]), max(want, allowed[1])) if (
                allowed and _is_number(allowed[0])) else (want, want)
            # Where round-off flipped a decision the figure is known to within its spread:
            # another platform's flip may land a little outside the few recorded.
            tol = max(REL_TOL * max(abs(lo), abs(hi)), ABS_TOL, hi - lo)
            if not lo - tol <= value <= hi + tol:
                diffs.append(f"{path}: {value!r} outside [{lo!r}, {hi!r}] +- {tol:.3g}")
        elif value != want and json.dumps(value) not in (allowed or []):
            diffs.append(f"{path}: {value!r} != {want!r}")
    return diffs


def platform() -> dict:
    """What the bits depend on besides our code: numpy picks its SIMD kernels by CPU feature,
    OpenBLAS its kernels by CPU model (two CPUs with the same features rounded differently),
    glibc's libm its variants of sin and exp."""
    from numpy._core._multiarray_umath import __cpu_features__
    from threadpoolctl import threadpool_info

    return {"numpy": np.__version__, "scipy": scipy.__version__, "python": sys.version.split()[0],
            "libc": "-".join(py_platform.libc_ver()),
            "cpu": _cpu_model(),
            "blas": sorted(f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')}"
                           for i in threadpool_info()),
            "cpu_features": sorted(k for k, on in __cpu_features__.items() if on)}


def _cpu_model() -> str:
    keys = ("vendor_id", "cpu family", "model", "model name", "stepping")
    found: dict[str, str] = {}
    with contextlib.suppress(OSError), open("/proc/cpuinfo", encoding="utf-8") as fh:
        for line in fh:
            key, _, value = line.partition(":")
            if key.strip() in keys and key.strip() not in found:
                found[key.strip()] = value.strip()
            if not line.strip() and found:
                break
    return " / ".join(found.get(k, "?") for k in keys) if found else py_platform.processor()


def all_figures() -> dict:
    base = load_config(CONFIG_NAME)
    golden: dict[str, Any] = {"platform": platform(), "perturbations": list(PERTURBATIONS),
                              "programs": {}, "spread": {}}
    for p in programs():
        nominal = figures(p)
        runs = [nominal] + [figures(p, perturbed(base, rel)) for rel in PERTURBATIONS]
        golden["programs"][p.name] = nominal
        golden["spread"][p.name] = spread(runs)
        print(f"{p.name}: {len(golden['spread'][p.name])} figures vary under round-off",
              file=sys.stderr)
    return golden


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/simulate_golden.py --write")
    GOLDEN.write_text(json.dumps(all_figures(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"wrote {GOLDEN}")
