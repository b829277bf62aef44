"""Plans that hold on the machine: each program planned without and with a servo band
(`axes.<a>.servo_band`), each plan run through every plant of the band.

A plan is computed once per config (`simulate`, ph-lookahead). Its frames are what the motion
loop sends: pre-compensated on the NOMINAL model (the loop does not know the plant). Each plant
then follows those frames, and the true contour error (the plant's distance from the programmed
path, settling included) is measured as bench/mismatch.py does. The plants are the 17 the
generator checks (the model and every combination of the X and Y corners, servo/band.py) and,
to test the claim that corners suffice, 48 more: an axis at the midpoint of one of its band's
edges, the other at a corner or a midpoint.

    python bench/band.py [--programs ...] [--pole-pct 20] [--gain-pct 10] [--config xy_table]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import peers  # noqa: E402

from controller.config import MachineConfig, ServoBand, load_config  # noqa: E402
from controller.interpreter.program import read_program  # noqa: E402
from controller.runtime.simulation import simulate  # noqa: E402
from controller.servo.model import mismatched  # noqa: E402

REPO = HERE.parent
PROGRAMS = ("nc_programs/naca2415.nc", "nc_programs/naca2415_loop.nc", "nc_programs/butterfly.nc")


def with_band(config: MachineConfig, pole_pct: float, gain_pct: float) -> MachineConfig:
    band = ServoBand(pole_pct, gain_pct)
    axes = tuple(replace(a, servo_band=band) if a.name in ("x", "y") else a for a in config.axes)
    return replace(config, axes=axes)


def plant(config: MachineConfig, x: tuple[float, float], y: tuple[float, float]) -> MachineConfig:
    """The machine whose X loop is the model mismatched by x = (pole %, lag %), Y by y."""
    off = {"x": x, "y": y}
    axes = tuple(replace(a, servo=mismatched(a.servo, *off[a.name])) if a.name in off else a
                 for a in config.axes)
    return replace(config, axes=axes)


def plants(pole: float, gain: float) -> tuple[list, list]:
    """(the generator's 17 plants, 48 more with an edge's midpoint on an axis), as (x, y)
    offsets (pole %, lag %)."""
    corners = [(p, g) for p in (-pole, pole) for g in (-gain, gain)]
    mids = [(0.0, -gain), (0.0, gain), (-pole, 0.0), (pole, 0.0)]
    checked = [((0.0, 0.0), (0.0, 0.0)), *itertools.product(corners, corners)]
    extra = [c for c in itertools.product(corners + mids, corners + mids)
             if c[0] in mids or c[1] in mids]
    return checked, extra


def label(x: tuple[float, float], y: tuple[float, float]) -> str:
    def one(o: tuple[float, float]) -> str:
        return f"{o[0]:+g}/{o[1]:+g}"
    return "model" if x == y == (0.0, 0.0) else (f"both {one(x)}" if x == y
                                                   else f"X {one(x)} Y {one(y)}")


def run_program(program: str, nominal: MachineConfig, banded: MachineConfig, pole: float,
                gain: float) -> None:
    blocks = list(read_program(program, nominal))
    path = peers.PathDistance(peers.path_polyline(blocks))
    origin = peers.np.zeros(2)
    checked, extra = plants(pole, gain)
    limit_um = nominal.interpolator.contour_error_limit_mm * 1e3
    results = {}
    for name, cfg in (("nominal plan", nominal), ("band plan", banded)):
        cpu0 = time.process_time()
        traj = simulate(blocks, cfg, "ph-lookahead")
        cpu = time.process_time() - cpu0
        frames = (peers.compensated(traj.ref_mm, origin, cfg)
                  if cfg.interpolator.servo_precompensation else traj.ref_mm[:, :2])
        motion_s = len(traj.t_s) * cfg.sample_period_s
        per = {}
        for x, y in checked + extra:
            m = peers.measure(traj.ref_mm, origin, motion_s, path, plant(nominal, x, y),
                              frames_mm=frames)
            per[(x, y)] = m.true_max_um
        rounds = sum(r.dynamics_rounds for r in traj.runs)
        results[name] = (motion_s, per, rounds, cpu)
    base_s = results["nominal plan"][0]
    print(f"`{Path(program).name}`: worst true contour error (um, limit {limit_um:g}) per plant; "
          f"band +-{pole:g} % poles, +-{gain:g} % lags\n")
    print("| plan | motion (s) | / nominal | dynamics rounds | planning CPU (s) | model | "
          "worst of the 17 checked | worst of 48 more (edge midpoints) | worst plant |")
    print("|---" * 9 + "|")
    for name, (motion_s, per, rounds, cpu) in results.items():
        worst_checked = max(checked, key=lambda c: per[c])
        worst_extra = max(extra, key=lambda c: per[c])
        print(f"| {name} | {motion_s:.3f} | {motion_s / base_s:.3f} | {rounds} | {cpu:.2f} | "
              f"{per[checked[0]]:.1f} | {per[worst_checked]:.1f} | {per[worst_extra]:.1f} | "
              f"{label(*worst_checked)} |")
    print("\nPer plant alike on both axes (pole % / lag %):\n")
    print("| plan | " + " | ".join(label(c, c) for c in
                                    [(0.0, 0.0)] + [c[0] for c in checked[1:] if c[0] == c[1]])
          + " |")
    print("|---" * 6 + "|")
    for name, (_, per, _, _) in results.items():
        same = [checked[0]] + [c for c in checked[1:] if c[0] == c[1]]
        print(f"| {name} | " + " | ".join(f"{per[c]:.1f}" for c in same) + " |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--programs", nargs="+", default=[str(REPO / p) for p in PROGRAMS])
    ap.add_argument("--config", help="machine configuration (default: the built-in one)")
    ap.add_argument("--pole-pct", type=float, default=20.0)
    ap.add_argument("--gain-pct", type=float, default=10.0)
    args = ap.parse_args()
    nominal = load_config(args.config)
    banded = with_band(nominal, args.pole_pct, args.gain_pct)
    for program in args.programs:
        run_program(program, nominal, banded, args.pole_pct, args.gain_pct)


if __name__ == "__main__":
    main()
