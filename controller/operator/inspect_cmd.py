"""`cncctl inspect PROGRAM`: the NURBS blocks as the planner sees them (corners, PH segments)."""

from __future__ import annotations

import argparse
import json
import sys

from controller.config import CONFIG_HELP, load_config
from controller.errors import ConfigError, NcError
from controller.operator.inspect_report import format_report, inspect_blocks
from controller.operator.outputs import OutputError, plot_path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("program", help="G-code program file")
    parser.add_argument("--config", help=CONFIG_HELP)
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--plot", metavar="PNG", help="write a plot of curves, zones and kappa")


def run(args: argparse.Namespace) -> int:
    from controller.interpreter.program import read_program  # late: keeps `cncctl --help` light

    try:
        config = load_config(args.config)
        plot = plot_path(args.plot) if args.plot is not None else None
        report = inspect_blocks(read_program(args.program, config), config)
    except ConfigError as exc:
        print(f"cncctl: config error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        print(f"cncctl: error: {exc}", file=sys.stderr)
        return 2
    except NcError as exc:
        print(exc.format(), file=sys.stderr)
        return 2
    print(json.dumps(report.to_json(), indent=2) if args.json else format_report(report))
    if plot is not None:
        from controller.operator.inspect_plot import plot_report

        plot_report(report, plot)
    return 0
