"""`cncctl simulate`: plan a program headless in virtual time and report Table IV's figures."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import TYPE_CHECKING, TextIO

import numpy as np

from controller.config import CONFIG_HELP, MachineConfig, load_config
from controller.errors import CncError, NcError
from controller.generator.plan import Algorithm
from controller.interpreter.program import read_program
from controller.operator.check_cmd import KEEP_BLOCKS, KEEP_LINES, check_program
from controller.operator.kept_blocks import KeptBlocks
from controller.operator.outputs import OutputError, output_path, plot_path
from controller.runtime.simulate_figures import Figures
from controller.runtime.simulate_stream import SampleBlock
from controller.runtime.simulation import limit_um, simulate_stream
from controller.servo.precompensation import Precompensator

if TYPE_CHECKING:  # imported where used: a run without --plot or a terminal needs neither
    from controller.operator.simulate_plot import PlotSeries
    from controller.operator.simulate_view import SimulateView

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
    parser.add_argument("--config", help=CONFIG_HELP)
    parser.add_argument("--algorithm", default=Algorithm.PH_LOOKAHEAD.value,
                        choices=[a.value for a in Algorithm])
    parser.add_argument("--compare", action="store_true", help="run all four algorithms")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--trajectory", metavar="CSV",
                        help="write t,x_ref,y_ref,x_act,y_act,feed,x_cmd,y_cmd[,z_cmd]")
    parser.add_argument("--plot", metavar="PNG", help="feedrate and contour error along the path")
    parser.add_argument("--stats", action="store_true",
                        help="add how the plan was obtained: look-ahead windows, dynamics rounds")


def _check_whole_program(path: str, config: MachineConfig) -> KeptBlocks | None:
    """`cncctl check` first (syntax, travel limits, feeds): no planning on a program with an
    error. The program's blocks if it has at most KEEP_BLOCKS blocks other than G0/G1 lines
    and KEEP_LINES lines (planned as they are), else None (read again as it is planned, so a
    long program is never held whole)."""
    kept = KeptBlocks(KEEP_BLOCKS, KEEP_LINES, KEEP_BLOCKS)
    check_program(path, config, summary=False, keep=kept)
    return None if kept.full else kept


def _one(path: str, config: MachineConfig, algorithm: str, trajectory: str | None = None,
         plot: PlotSeries | None = None, stats: bool = False,
         view: SimulateView | None = None, checked: KeptBlocks | None = None) -> dict:
    """Simulate one algorithm, streaming: the figures, and the trajectory CSV, the plot's
    series and the terminal's progress bar if asked for, are gathered sample block by sample
    block (memory bounded). checked: the program's blocks, if the check kept them."""
    figures = Figures(len(config.axis_names), config.sample_period_s)
    sinks = [figures.add] + ([plot.add] if plot is not None else [])
    if view is not None:
        view.start(algorithm)
        sinks.append(view.add)
    writer = TrajectoryWriter(trajectory, config) if trajectory else None
    if writer is not None:
        sinks.append(writer.add)
    try:
        blocks = iter(checked) if checked is not None else read_program(path, config)
        cpu = simulate_stream(blocks, config, algorithm, sinks, figures.runs.add)
    except BaseException:
        if writer is not None:
            writer.abandon()
        raise
    if writer is not None:
        writer.close()
    out = figures.report(path, algorithm, limit_um(config), cpu)
    if stats:
        out["stats"] = figures.runs.stats()
    return out


class TrajectoryWriter:
    """`--trajectory CSV`, written as the samples come (%.9g, CRLF as the csv module writes):
    into CSV.part, renamed to CSV once the run is complete. One row per sample, the settling
    after the end included (SETTLE_S at the end point). x_cmd, y_cmd (z_cmd) are what the motion
    loop sends the drives for those samples: the wanted path through the servo
    pre-compensation when the config has it (the path itself otherwise), in mm before rounding
    to pulses, so that an outside servo model can be run on them."""

    def __init__(self, path: str, config: MachineConfig) -> None:
        self.path, self.part = path, path + ".part"
        self.T = config.sample_period_s  # noqa: N815
        names = config.axis_names
        cmd_cols = [f"{a}_cmd" for a in names]
        self.ROW = ",".join(["%.9g"] * (6 + len(cmd_cols))) + "\r\n"
        start = np.zeros(len(names))  # simulate starts at rest at X0 Y0 (Z0)
        self.precomp = (Precompensator([a.servo for a in config.axes], self.T, start)
                        if config.interpolator.servo_precompensation else None)
        try:
            self.fh: TextIO = open(self.part, "w", encoding="utf-8", newline="")  # noqa: SIM115
            self.fh.write(",".join(["t", "x_ref", "y_ref", "x_act", "y_act", "feed",
                                    *cmd_cols]) + "\r\n")
        except OSError as exc:
            raise OutputError(f"--trajectory {path}: {exc.strerror}") from None

    def add(self, b: SampleBlock) -> None:
        try:
            self._add(b)
        except OSError as exc:  # a full disk: the run ends with the reason, .part removed
            raise OutputError(f"--trajectory {self.path}: {exc.strerror}") from None

    def _add(self, b: SampleBlock) -> None:
        n = len(b)
        if n == 0:
            return
        ref = b.ref_mm
        cmd = ref if self.precomp is None else self.precomp.push(ref)
        rows = np.column_stack([np.arange(b.i0 + 1, b.i0 + n + 1) * self.T, ref[:, 0], ref[:, 1],
                                ref[:, 0] - b.ex_mm, ref[:, 1] - b.ey_mm, b.feed_mm_s, cmd])
        fmt = self.ROW
        self.fh.write("".join([fmt % tuple(r) for r in rows.tolist()]))

    def close(self) -> None:
        try:
            self.fh.close()
            os.replace(self.part, self.path)
        except OSError as exc:
            self.abandon()
            raise OutputError(f"--trajectory {self.path}: {exc.strerror}") from None

    def abandon(self) -> None:
        try:
            self.fh.close()
        except OSError:
            pass  # the data that did not fit goes with the file
        try:
            os.unlink(self.part)
        except FileNotFoundError:
            pass


def _plot_series(config: MachineConfig, algorithms: list[str]) -> dict[str, PlotSeries]:
    from controller.operator.simulate_plot import PlotSeries

    return {a: PlotSeries(config) for a in algorithms}


def _view(program: str, config: MachineConfig) -> SimulateView:
    from controller.operator.simulate_view import SimulateView

    return SimulateView(program, config.sample_period_s, sys.stderr)


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
        if args.trajectory is not None:
            args.trajectory = output_path(args.trajectory, "--trajectory")
        if args.plot is not None:
            args.plot = plot_path(args.plot)
        checked = _check_whole_program(args.program, config)
        algorithms = [a.value for a in Algorithm] if args.compare else [args.algorithm]
        chosen = args.algorithm if args.compare else algorithms[-1]
        series = _plot_series(config, algorithms) if args.plot else {}
        view = _view(args.program, config) if sys.stderr.isatty() else None
        try:
            reports = [_one(args.program, config, a, args.trajectory if a == chosen else None,
                            series.get(a), args.stats, view, checked) for a in algorithms]
        finally:
            if view is not None:
                view.close()
    except NcError as exc:
        print(exc.format(), file=sys.stderr)
        return 2
    except CncError as exc:
        print(f"cncctl: error: {exc}", file=sys.stderr)
        return 2
    picked = next(r for r in reports if r["algorithm"] == chosen)
    if args.plot:
        from controller.operator.simulate_plot import plot_simulation

        try:
            plot_simulation(args.plot, [series[a] for a in algorithms], reports, config)
        except OSError as exc:
            print(f"cncctl: error: --plot {args.plot}: {exc.strerror}", file=sys.stderr)
            return 2
    code = 0 if picked["contour_limit_met"] else 1
    if args.json:
        out = {"program": args.program, "results": reports} if args.compare else reports[0]
        print(json.dumps(out, indent=2))
    elif args.compare:
        print(format_table(args.program, reports))
    else:
        _print_summary(reports[0])
    if code:
        print(limit_message(picked, config), file=sys.stderr)
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
