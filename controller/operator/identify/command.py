"""`cncctl identify [AXES]`: excite each axis within a window shown first, fit the eq. 27 loop
to what the encoders measured, and show it beside the model in force (embedded runs)."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Any

from controller.config import CONFIG_HELP, MachineConfig, ServoParams, load_config
from controller.errors import CncError, ConfigError
from controller.operator.client import daemon_answers, default_socket_path
from controller.operator.drive_args import add_drive_option_argument, config_with_drive_options
from controller.operator.identify.loop import (
    LEAD_IN_S,
    TAIL_S,
    AxisRecord,
    StopRequest,
    excite_axis,
)
from controller.operator.identify.report import (
    contour_meaning,
    fit_lines,
    meaning_lines,
    parameter_lines,
    write_config,
)
from controller.operator.outputs import OutputError, output_path
from controller.operator.run.exit_codes import EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run.from_line import home_all
from controller.runtime.processes import build_drive, open_drive
from controller.servo.excitation import Excitation, design
from controller.servo.fit import AxisFit, fit_axis
from drivers.base import Drive
from drivers.errors import DriveUnavailableError, HomingError

EXIT_REFUSED_FIT = 1  # it moved, but the identified model is refused: nothing written
EXIT_FAULT, EXIT_ABORTED = 3, 4
MIN_FIT_PCT = 80.0  # held-out fit below this: the loop is not explained, nothing written
MIN_WINDOW_SHARE = 0.5  # the travel may shrink the excitation to half, not further
UNBOUNDED_MM = 1e6


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


def _say(text: str) -> None:
    print(f"cncctl: {text}", file=sys.stderr, flush=True)


def _axes(config: MachineConfig, words: list[str]) -> list[int]:
    names = [w.lower() for w in words] or list(config.axis_names)
    for n in names:
        if n not in config.axis_names:
            raise ConfigError("identify", n, f"no such axis (the machine has "
                              f"{', '.join(a.upper() for a in config.axis_names)})")
    return [config.axis_names.index(n) for n in dict.fromkeys(names)]


def _output(args: argparse.Namespace) -> str | None:
    if args.output is None:
        return None
    real = output_path(args.output, "--output")
    if os.path.exists(real) and not args.force:
        raise OutputError(f"--output {args.output}: exists; --force replaces it")
    return real


def run(args: argparse.Namespace) -> int:
    if default_socket_path() and os.path.exists(default_socket_path()) \
            and daemon_answers(default_socket_path()):
        _say(f"a cncd answers on {default_socket_path()} and owns the drive; identify runs "
             "embedded only: stop cncd first. Nothing moved")
        return EXIT_REJECTED
    try:
        if not 1.0 <= args.duration <= 30.0 or not args.window > 0:
            raise ConfigError("identify", "--duration/--window",
                              "duration 1 to 30 s, window above 0 mm")
        config = config_with_drive_options(load_config(args.config), args.drive_option)
        axes = _axes(config, args.axes)
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
    plans, problem = _plans(config, drive, axes, args)
    if problem is not None:
        _say(problem + ". Nothing moved")
        return EXIT_REJECTED
    if not _confirm(args):
        _say("not confirmed: nothing moved")
        return EXIT_REJECTED
    return _excite_and_fit(args, config, drive, plans, out)


def _plans(config: MachineConfig, drive: Drive, axes: list[int],
           args: argparse.Namespace) -> tuple[list[tuple[int, Excitation]], str | None]:
    """Each axis's excitation within Vmax, Amax, the window and the travel, shown; or why
    one cannot be made."""
    cmd, _ = drive.position_counts()
    vmax = config.interpolator.max_feed_mm_s
    amax = config.interpolator.max_accel_mm_s2
    plans = []
    for i in axes:
        a = config.axes[i]
        here = float(cmd[i]) * a.pulse_mm
        # What Vmax and Amax alone allow; the window and the travel may cut it to half.
        wanted = design(config.sample_period_s, min(vmax, a.max_velocity_mm_s), amax,
                        UNBOUNDED_MM, args.duration)
        need = max(-wanted.excursion_mm[0], wanted.excursion_mm[1])
        room = min(args.window, here - a.travel_mm[0], a.travel_mm[1] - here)
        if room < MIN_WINDOW_SHARE * need:
            return [], (f"travel too short: {a.name.upper()} stands at {here:.3f} mm, "
                        f"{max(room, 0.0):.3f} mm from its travel limit or the --window; "
                        f"identify needs {need:.3f} mm either side")
        exc = wanted if room >= need else design(
            config.sample_period_s, min(vmax, a.max_velocity_mm_s), amax, room, args.duration)
        lo, hi = exc.excursion_mm
        _say(f"{a.name.upper()} will move within {here + lo:.3f}..{here + hi:.3f} mm "
             f"(now {here:.3f}; up to {exc.peak_velocity_mm_s:.1f} mm/s and "
             f"{exc.peak_accel_mm_s2:.0f} mm/s^2, "
             f"{LEAD_IN_S + args.duration + TAIL_S:.1f} s); the other axes hold")
        plans.append((i, exc))
    return plans, None


def _confirm(args: argparse.Namespace) -> bool:
    if args.yes:
        return True
    previous: dict[int, Any] = {}

    def cancel(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt
    try:
        for sig in STOP_SIGNALS:
            previous[sig] = signal.signal(sig, cancel)
        _say("press Enter to start, Ctrl-C to cancel")
        return sys.stdin.readline() != ""
    except (KeyboardInterrupt, OSError):
        return False
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _excite_and_fit(args: argparse.Namespace, config: MachineConfig, drive: Drive,
                    plans: list[tuple[int, Excitation]], out: str | None) -> int:
    stop = StopRequest()

    def on_signal(signum: int, frame: Any) -> None:
        stop.request_abort(f"aborted by operator ({signal.Signals(signum).name})")
    previous = {sig: signal.signal(sig, on_signal) for sig in STOP_SIGNALS}
    records: list[AxisRecord] = []
    try:
        for i, exc in plans:
            _say(f"exciting {config.axes[i].name.upper()}")
            rec = excite_axis(drive, config, i, exc, stop, args.virtual_time)
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
    fits: dict[str, AxisFit] = {}
    for rec in records:
        try:
            fits[rec.axis] = _fit(config, rec)
        except ValueError as exc:
            _say(f"{rec.axis.upper()}: {exc}; nothing written")
            return EXIT_REFUSED_FIT
    lines: list[str] = []
    for name, fit in fits.items():
        lines += fit_lines(name, fit, MIN_FIT_PCT)
    for name, fit in fits.items():
        lines += parameter_lines(name, config.axis(name).servo, fit.params)
    refused = [n for n, f in fits.items() if f.problem is not None or f.fit_pct < MIN_FIT_PCT]
    identified: dict[str, ServoParams] = {n: f.params for n, f in fits.items()}
    if not refused:
        meaning = contour_meaning(config, identified)
        if meaning is not None:
            lines += meaning_lines(meaning)
    print("\n".join(lines), flush=True)
    if refused:
        _say(f"the identified loop of {', '.join(n.upper() for n in refused)} is refused: "
             "nothing written")
        return EXIT_REFUSED_FIT
    if out is not None:
        try:
            write_config(config, identified, out)
        except (OSError, CncError) as exc:
            _say(f"--output {out}: {exc}")
            return EXIT_FAULT
        _say(f"wrote {out}")
    return 0


def _fit(config: MachineConfig, rec: AxisRecord) -> AxisFit:
    axis = config.axis(rec.axis)
    return fit_axis(rec.commanded_counts * axis.pulse_mm, rec.encoder_counts * axis.pulse_mm,
                    axis.servo, config.sample_period_s, rec.rest_samples, rec.sample_index)
