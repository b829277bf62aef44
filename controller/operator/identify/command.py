"""`cncctl identify [AXES]`: excite each axis within a window shown first, fit the eq. 27 loop
to what the encoders measured, and show it beside the model in force: embedded, or through
the cncd that answers (identify/remote.py)."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Any

from controller.config import CONFIG_HELP, MachineConfig, load_config
from controller.errors import CncError, ConfigError
from controller.operator.client import (
    DaemonUnavailable,
    NoDaemon,
    daemon_answers,
    default_socket_path,
    socket_argument,
)
from controller.operator.drive_args import add_drive_option_argument, config_with_drive_options
from controller.operator.identify.loop import AxisRecord, StopRequest, excite_axis
from controller.operator.identify.plan import (
    AxisPlan,
    PlanRefused,
    check_limits,
    choose_axes,
    confirm_start,
    plan_axes,
)
from controller.operator.identify.remote import identify_on_daemon, refused_by_daemon
from controller.operator.identify.report import write_config
from controller.operator.identify.result import fit_records
from controller.operator.outputs import OutputError, output_path
from controller.operator.run.exit_codes import EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run.from_line import home_all
from controller.runtime.processes import build_drive, open_drive
from drivers.base import Drive
from drivers.errors import DriveUnavailableError, HomingError

EXIT_REFUSED_FIT = 1  # it moved, but the identified model is refused: nothing written
EXIT_FAULT, EXIT_ABORTED = 3, 4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("axes", nargs="*", metavar="AXIS",
                        help="axes to identify, one after the other (default: every axis)")
    parser.add_argument("--config", help=CONFIG_HELP)
    add_drive_option_argument(parser)
    parser.add_argument("--yes", action="store_true", help="do not ask before moving")
    parser.add_argument("--output", metavar="FILE",
                        help="write the config in force with the identified servo models")
    parser.add_argument("--force", action="store_true", help="with --output: replace FILE")
    parser.add_argument("--window", type=float, default=10.0, metavar="MM",
                        help="the farthest an axis may move either side of where it stands "
                             "(default 10; the travel limits narrow it)")
    parser.add_argument("--duration", type=float, default=4.0, metavar="S",
                        help="excitation per axis in seconds (default 4, 1 to 30)")
    parser.add_argument("--home", action="store_true",
                        help="home the axes that have a homing sequence first")
    parser.add_argument("--virtual-time", action="store_true",
                        help="clock the simulated card as fast as possible (no wall clock)")
    parser.add_argument("--socket", metavar="PATH", type=socket_argument,
                        help="identify through the cncd answering here (default: the one at "
                             "$CNCD_SOCKET or /run/cncd/cncd.sock, if it answers)")


def _say(text: str) -> None:
    print(f"cncctl: {text}", file=sys.stderr, flush=True)


def _output(args: argparse.Namespace) -> str | None:
    if args.output is None:
        return None
    real = output_path(args.output, "--output")
    if os.path.exists(real) and not args.force:
        raise OutputError(f"--output {args.output}: exists; --force replaces it")
    return real


def _daemon_socket(args: argparse.Namespace) -> str | None:
    """The daemon to identify through: --socket, or the default one if a daemon answers
    there. Without one, identify is embedded (this process opens the drive)."""
    if args.socket is not None:
        return str(args.socket)
    path = default_socket_path()
    return path if os.path.exists(path) and daemon_answers(path) else None


def run(args: argparse.Namespace) -> int:
    socket_path = _daemon_socket(args)
    if socket_path is not None:
        refusal = refused_by_daemon(args, socket_path)
        if refusal is not None:
            _say(refusal)
            return EXIT_REJECTED
        try:
            check_limits(args.window, args.duration)
            out = _output(args)
            return identify_on_daemon(args, socket_path, out)
        except (ConfigError, OutputError) as exc:
            _say(f"{exc} (nothing moved)")
            return EXIT_REJECTED
        except DaemonUnavailable as exc:  # no daemon at all: rejected; lost meanwhile: a fault
            _say(f"{exc}" + (" (nothing moved)" if isinstance(exc, NoDaemon) else ""))
            return EXIT_REJECTED if isinstance(exc, NoDaemon) else EXIT_FAULT
    try:
        check_limits(args.window, args.duration)
        config = config_with_drive_options(load_config(args.config), args.drive_option)
        axes = choose_axes(config, args.axes)
        out = _output(args)
    except (ConfigError, OutputError) as exc:
        _say(f"{exc} (nothing moved)")
        return EXIT_REJECTED
    try:
        drive = build_drive(config, args.virtual_time)
        open_drive(drive)
    except DriveUnavailableError as exc:
        _say(f"{exc} (nothing moved)")
        return EXIT_REJECTED
    try:
        return _identify(args, config, drive, axes, out)
    finally:
        drive.close()


def _identify(args: argparse.Namespace, config: MachineConfig, drive: Drive, axes: list[int],
              out: str | None) -> int:
    status = drive.status()
    if status.halted:
        _say(f"the drive is halted ({drive.fault_message()}): reset it first. Nothing moved")
        return EXIT_REJECTED
    if args.home:
        try:
            home_all(drive, config)
        except HomingError as exc:
            _say(f"{exc}; nothing identified")
            return EXIT_FAULT
    homed = drive.homed()
    unhomed = [config.axes[i].name.upper() for i in axes if not homed[i]]
    if unhomed and not config.allow_unhomed:
        _say(f"{', '.join(unhomed)} not homed: run with --home (the config's allow_unhomed "
             "permits it unhomed). Nothing moved")
        return EXIT_REJECTED
    try:
        cmd, _ = drive.position_counts()
        plans = plan_axes(config, [int(c) for c in cmd], axes, args.window, args.duration)
    except PlanRefused as exc:
        _say(f"{exc}. Nothing moved")
        return EXIT_REJECTED
    for plan in plans:
        _say(plan.window_text())
    if not confirm_start(args.yes):
        _say("not confirmed: nothing moved")
        return EXIT_REJECTED
    return _excite_and_fit(args, config, drive, plans, out)


def _excite_and_fit(args: argparse.Namespace, config: MachineConfig, drive: Drive,
                    plans: list[AxisPlan], out: str | None) -> int:
    stop = StopRequest()

    def on_signal(signum: int, frame: Any) -> None:
        stop.request_abort(f"aborted by operator ({signal.Signals(signum).name})")
    previous = {sig: signal.signal(sig, on_signal) for sig in STOP_SIGNALS}
    records: list[AxisRecord] = []
    try:
        for plan in plans:
            _say(f"exciting {plan.name.upper()}")
            rec = excite_axis(drive, config, plan.index, plan.excitation, stop,
                              args.virtual_time)
            records.append(rec)
            if rec.fault is not None or rec.stopped is not None:
                break
    except CncError as exc:
        _say(f"{exc}; nothing identified")
        return EXIT_FAULT
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    last = records[-1]
    if last.fault is not None:
        _say(f"{last.fault}; {last.axis.upper()} stopped, nothing identified")
        return EXIT_FAULT
    if last.stopped is not None:
        _say(f"{last.stopped}: {last.axis.upper()} brought back to rest at its start, "
             "nothing identified")
        return EXIT_ABORTED
    return _fit_and_report(config, records, out)


def _fit_and_report(config: MachineConfig, records: list[AxisRecord], out: str | None) -> int:
    result = fit_records(config, records)
    if result.problem is not None:
        _say(f"{result.problem}; nothing written")
        return EXIT_REFUSED_FIT
    print("\n".join(result.lines), flush=True)
    if result.refused:
        _say(f"the identified loop of {', '.join(n.upper() for n in result.refused)} is "
             "refused: nothing written")
        return EXIT_REFUSED_FIT
    if out is not None:
        try:
            write_config(config, result.identified, out)
        except (OSError, CncError) as exc:
            _say(f"--output {out}: {exc}")
            return EXIT_FAULT
        _say(f"wrote {out}")
    return 0
