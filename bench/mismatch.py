"""Model mismatch: ours and the tuned peers, planned on the nominal Table II
model, run through a plant that is not that model.

The plant's poles are moved by +-10 % and +-20 % (bandwidth off, DC gain kept), or its
feed-forward lags c1, c2 scaled by +-10 % and +-20 % (`mismatched` in
controller/servo/model.py; the sim card runs the same plant with the drive
options plant_pole_pct and plant_gain_pct). Each reference is planned once on the nominal model:
ours by `simulate` (pre-compensated: the frames sent lead the path by the nominal model's lag,
and the plant is not that model), Klipper and grbl at the acceleration tuned for the nominal
model at 1 um chords (bench/peers.py). Reported: the true contour error (distance of the
plant's actual position from the programmed path, settling included), which a machine would
measure.

    python bench/mismatch.py [--programs nc_programs/naca2415.nc nc_programs/butterfly.nc]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import peers  # noqa: E402

from controller.config import MachineConfig, load_config  # noqa: E402
from controller.interpreter.program import read_program  # noqa: E402
from controller.runtime.simulation import simulate  # noqa: E402
from controller.servo.model import mismatched_config  # noqa: E402
from controller.servo.prediction import planning_limit_mm  # noqa: E402

REPO = HERE.parent
CASES = [(0, 0), (-20, 0), (-10, 0), (10, 0), (20, 0), (0, -20), (0, -10), (0, 10), (0, 20)]


def references(program: str, config: MachineConfig) -> tuple[dict[str, tuple], object]:
    """name -> (frames sent (N, 2), start, motion s): ours (as configured and the other way,
    pre-compensated or not), and the peers tuned on the model."""
    ip = config.interpolator
    limit_um = planning_limit_mm(config) * 1e3
    blocks = list(read_program(program, config))
    path = peers.PathDistance(peers.path_polyline(blocks))
    out = {}
    origin = peers.np.zeros(2)
    for name, cfg in peers.ours_variants(config):
        traj = simulate(blocks, cfg, "ph-lookahead")
        frames = (peers.compensated(traj.ref_mm, origin, cfg)
                  if cfg.interpolator.servo_precompensation else traj.ref_mm[:, :2])
        out[name.removeprefix("ours: ph-lookahead, ")] = (
            frames, origin, len(traj.t_s) * cfg.sample_period_s)
    pts = peers.flatten(blocks, 1e-3)
    T = config.sample_period_s  # noqa: N806
    planners = {
        "Klipper tuned": lambda a: peers.klipper_plan(pts, ip.max_feed_mm_s, ip.max_feed_mm_s, a),
        "grbl tuned": lambda a: peers.grbl_plan(pts, ip.max_feed_mm_s, ip.max_feed_mm_s, a),
    }
    samplers = {"Klipper tuned": peers.sample_moves, "grbl tuned": peers.sample_grbl_segments}
    for name, plan in planners.items():
        def evaluate(a: float, plan=plan, name=name) -> peers.Measured:
            moves = plan(a)
            return peers.measure(samplers[name](moves, T), pts[0], moves.duration_s, path,
                                 config)
        accel, _ = peers.tune(evaluate, limit_um, ip.max_accel_mm_s2)
        moves = plan(accel)
        out[name] = (samplers[name](moves, T), pts[0], moves.duration_s)
    return out, path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--programs", nargs="+", default=[str(REPO / "nc_programs/naca2415.nc"),
                                                      str(REPO / "nc_programs/butterfly.nc")])
    ap.add_argument("--config", help="machine configuration (default: the built-in one)")
    args = ap.parse_args()
    nominal = load_config(args.config)
    for program in args.programs:
        refs, path = references(program, nominal)
        names = list(refs)
        print(f"`{Path(program).name}`: true contour error max (um) on a mismatched plant "
              f"(limit {nominal.interpolator.contour_error_limit_mm * 1e3:g} um)\n")
        print("| plant | " + " | ".join(names) + " |")
        print("|---" * (len(names) + 1) + "|")
        for pole, gain in CASES:
            plant = mismatched_config(nominal, pole, gain)
            cells = []
            for name in names:
                ref, start, motion_s = refs[name]
                m = peers.measure(ref, start, motion_s, path, plant)
                cells.append(f"{m.true_max_um:.1f}")
            label = ("nominal" if (pole, gain) == (0, 0) else
                     f"poles {pole:+d} %" if pole else f"lags {gain:+d} %")
            print(f"| {label} | " + " | ".join(cells) + " |")
        print()


if __name__ == "__main__":
    main()
