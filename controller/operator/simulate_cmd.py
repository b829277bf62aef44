"""`cncctl simulate`: plan a program headless in virtual time and report Table IV's figures."""

from __future__ import annotations

import argparse
import csv
import json
import sys

import numpy as np

from controller.config import MachineConfig, load_config
from controller.errors import CncError, NcError
from controller.generator.plan import Algorithm
from controller.interpreter.program import read_program
from controller.operator.check_cmd import check_program
from controller.runtime.simulation import Trajectory, report, simulate

TABLE_ROWS = (
    ("X tracking error max (um)", lambda r: r["tracking_error_um"]["x"]["max"]),
    ("X tracking error RMS (um)", lambda r: r["tracking_error_um"]["x"]["rms"]),
    ("Y tracking error max (um)", lambda r: r["tracking_error_um"]["y"]["max"]),
    ("Y tracking error RMS (um)", lambda r: r["tracking_error_um"]["y"]["rms"]),
    ("Contour error max (um)", lambda r: r["contour_error_um"]["max"]),
    ("Contour error RMS (um)", lambda r: r["contour_error_um"]["rms"]),
    ("Contour error mean (um)", lambda r: r["contour_error_um"]["mean"]),
    ("True contour error max (um)", lambda r: r["contour_error_true_um"]["max"]),
    ("Time (s)", lambda r: r["motion_time_s"]),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("program", help="G-code program")
    parser.add_argument("--config", help="machine configuration (YAML file or built-in name)")
    parser.add_argument("--algorithm", default=Algorithm.PH_LOOKAHEAD.value,
                        choices=[a.value for a in Algorithm])
    parser.add_argument("--compare", action="store_true", help="run all four algorithms")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--trajectory", metavar="CSV", help="write t,x_ref,y_ref,x_act,y_act,feed")
    parser.add_argument("--plot", metavar="PNG", help="feedrate and contour error along the path")


def _check_whole_program(path: str, config: MachineConfig) -> None:
    """`cncctl check` first (syntax, travel limits, feeds): no planning on a program with an
    error."""
    check_program(path, config)


def _one(path: str, config: MachineConfig, algorithm: str) -> tuple[dict, Trajectory]:
    traj = simulate(read_program(path, config), config, algorithm)
    return report(traj, path, algorithm, config), traj


def write_trajectory(path: str, traj: Trajectory) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x_ref", "y_ref", "x_act", "y_act", "feed"])
        rows = np.column_stack([traj.t_s, traj.ref_mm[:, 0], traj.ref_mm[:, 1],
                                traj.act_mm[:, 0], traj.act_mm[:, 1], traj.feed_mm_s])
        w.writerows([f"{v:.9g}" for v in row] for row in rows)


def format_table(program: str, results: list[dict]) -> str:
    """Table IV's layout: rows of errors and time, one column per algorithm."""
    names = [r["algorithm"] for r in results]
    width = max(len(n) for n in names) + 2
    lines = [f"{program}", f"{'':28}" + "".join(f"{n:>{width}}" for n in names)]
    for label, get in TABLE_ROWS:
        lines.append(f"{label:28}" + "".join(f"{get(r):>{width}.4f}" for r in results))
    return "\n".join(lines)


def _print_summary(r: dict) -> None:
    print(format_table(r["program"], [r]))
    print(f"max feed {r['max_feed_mm_s']:.3f} mm/s, max tangential accel "
          f"{r['max_tangential_accel_mm_s2']:.1f} mm/s^2, sharp corners {r['sharp_corners']}, "
          f"PH segments {r['ph_segments']}, dynamics rounds {r['dynamics_rounds']}, "
          f"planning CPU {r['planning_cpu_s']:.3f} s")



def run(args: argparse.Namespace) -> int:
    try:
        config = load_config(args.config)
        _check_whole_program(args.program, config)
        algorithms = [a.value for a in Algorithm] if args.compare else [args.algorithm]
        results = [_one(args.program, config, a) for a in algorithms]
    except NcError as exc:
        print(exc.format(), file=sys.stderr)
        return 2
    except CncError as exc:
        print(f"cncctl: error: {exc}", file=sys.stderr)
        return 2
    chosen = results[-1] if not args.compare else next(
        (x for x in results if x[0]["algorithm"] == args.algorithm), results[-1])
    if args.trajectory:
        write_trajectory(args.trajectory, chosen[1])
    if args.plot:
        from controller.operator.simulate_plot import plot_simulation

        plot_simulation(args.plot, [t for _, t in results], [r for r, _ in results], config)
    reports = [r for r, _ in results]
    code = 0 if chosen[0]["contour_limit_met"] else 1
    if args.json:
        out = {"program": args.program, "results": reports} if args.compare else reports[0]
        print(json.dumps(out, indent=2))
    elif args.compare:
        print(format_table(args.program, reports))
    else:
        _print_summary(reports[0])
    if code:
        print(limit_message(chosen[0], config), file=sys.stderr)
    return code


def limit_message(r: dict, config: MachineConfig) -> str:
    """Why the chosen plan breaks the contour limit, naming the worst place."""
    true, limit_um = r["contour_error_true_um"], config.interpolator.contour_error_limit_mm * 1e3
    at = true["at"] or {}
    where = (f"at t {at.get('t_s', 0):.3f} s, line {at.get('line', 0)}, X{at.get('x_mm', 0):.4f} "
             f"Y{at.get('y_mm', 0):.4f}" + (" (settling after the end)"
                                              if at.get("after_end") else ""))
    return (f"cncctl simulate: {r['algorithm']} breaks the contour error limit: the tool is "
            f"{true['max']:.1f} um from the path (limit {limit_um:g} um) {where}")
