"""`cncctl run PROGRAM`: check the whole program, then run it through the three-process runtime."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from dataclasses import replace
from typing import Any

from controller.config import CONFIG_HELP, load_config
from controller.errors import CncError, ConfigError, NcError, OffsetsError
from controller.motion.realtime import probe_scheduling
from controller.motion.types import MotionProgress, MotionState, Outcome
from controller.offsets import ProgramOffsets, load_offsets
from controller.operator.client import (
    DaemonUnavailable,
    NoDaemon,
    daemon_answers,
    default_socket_path,
    refused_through_daemon,
    socket_argument,
)
from controller.operator.drive_args import add_drive_option_argument, config_with_drive_options
from controller.operator.run.exit_codes import EXIT_CODES, EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run.from_line import HomingAborted, Sequence, run_from_line
from controller.operator.run.io_announce import ToolChanges
from controller.operator.run.keys import KeyControl, read_keys, stdin_fd
from controller.operator.run.view import JsonView, PlainView, ProgramLines, RichView
from controller.runtime.gc_policy import fewer_collections
from controller.runtime.processes import Runtime, RuntimeOptions
from controller.runtime.stages import checked_blocks
from controller.tools import ToolTableError, load_tool_table
from drivers.errors import DriveUnavailableError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("program", help="G-code program to run")
    parser.add_argument("--config", help=CONFIG_HELP)
    parser.add_argument("--json", action="store_true", help="one JSON object per line")
    add_drive_option_argument(parser)
    parser.add_argument("--from-line", type=int, metavar="N",
                        help="run from line N: modes, feed, offsets and position brought there "
                             "without motion, then a straight approach the operator confirms")
    parser.add_argument("--home", action="store_true",
                        help="embedded runs: home the axes that have a homing sequence first")
    parser.add_argument("--yes", action="store_true",
                        help="with --from-line: do not ask before the approach")
    parser.add_argument("--offsets", metavar="FILE",
                        help="embedded runs: work offset table (JSON) in force")
    parser.add_argument("--tools", metavar="TBL",
                        help="embedded runs: tool table (LinuxCNC tool.tbl) in force, in place "
                             "of the config's tools.table_file")
    parser.add_argument("--optional-stop", action="store_true",
                        help="M1 pauses like M0 (optional stop on)")
    parser.add_argument("--virtual-time", action="store_true",
                        help="clock the simulated card as fast as possible (no wall clock)")
    parser.add_argument("--socket", metavar="PATH", type=socket_argument,
                        help="run through the cncd answering here (default: the one at "
                             "$CNCD_SOCKET or /run/cncd/cncd.sock if it answers, else embedded)")


def check_program(path: str, config: Any, **kw: Any) -> None:
    """The whole program through `cncctl check` (syntax, travel limits, feeds), no motion:
    raises NcError at the first error."""
    from controller.operator.check_cmd import check_program as check_whole_program

    check_whole_program(path, config, **kw)


def _view(args: argparse.Namespace, path: str) -> Any:
    if args.json:
        return JsonView()
    # The status line's text is read from the file as shown, not held for the whole program
    # (this process is the motion process: see ProgramLines).
    lines = ProgramLines(path)
    return RichView(lines) if sys.stdout.isatty() else PlainView(lines)


class _Announcer:
    """Says once per standstill (M0 pause, feed hold) how to continue; passes progress on."""

    def __init__(self, inner: Any, keys: KeyControl, tools: ToolChanges | None = None) -> None:
        self.inner, self.keys, self.last = inner, keys, MotionState.WAITING
        self.tools = tools

    def progress(self, p: MotionProgress) -> None:
        self.keys.progress(p)
        if p.state is not self.last and p.state is MotionState.PAUSED:
            change = None if self.tools is None else self.tools.prompt(p.line)
            print(f"cncctl: {change or f'paused at line {p.line} (M0)'}: press Enter to "
                  "resume, Ctrl-C to stop", file=sys.stderr, flush=True)
            if self.tools is not None:
                self.tools.at_pause(p)
        elif p.state is not self.last and p.state is MotionState.HELD:
            where = " ".join(f"{n}{v:.3f}" for n, v in zip("XYZ", p.position_mm, strict=False))
            print(f"cncctl: held at line {p.line}, {where}: press space or Enter to resume",
                  file=sys.stderr, flush=True)
        self.last = p.state
        self.inner(p)


def _event_to(view: Any) -> Any:
    """An I/O event dict (controller/io_events.py) out through the view's event line."""
    return lambda e: view.event(e["event"], **{k: v for k, v in e.items() if k != "event"})


def _daemon_socket(args: argparse.Namespace) -> str | None:
    """The daemon to run through: --socket, or the default one if a daemon answers there.
    Without one, the run is embedded (the drive is opened by this process)."""
    if args.socket is not None:
        return str(args.socket)
    path = default_socket_path()
    return path if os.path.exists(path) and daemon_answers(path) else None


# Options of an embedded run that a daemon cannot honour: it owns the drive, its config and
# its offset table, and runs in real time. They were dropped without a word (a --virtual-time
# dry run moved the serial drive in real time); now the run is refused, nothing sent.
_NOT_THROUGH_DAEMON = (
    ("virtual_time", "--virtual-time", "the daemon's drive runs in real time"),
    ("config", "--config", "the daemon runs with its own config (cncd --config)"),
    ("drive_option", "--drive-option", "the daemon's drive is set in its config"),
    ("home", "--home", "home through the daemon first: `cncctl home`"),
    ("offsets", "--offsets", "the daemon keeps its own table: `cncctl offset`"),
    ("tools", "--tools", "the daemon keeps its own tool table: `cncctl tool`"),
)


def _refused_by_daemon(args: argparse.Namespace, socket_path: str) -> str | None:
    """Why this run cannot go through the daemon as asked (None: it can)."""
    refusal = refused_through_daemon(args, socket_path, _NOT_THROUGH_DAEMON, "run")
    return None if refusal is None else f"cncctl: {refusal}"


def run(args: argparse.Namespace) -> int:
    socket_path = _daemon_socket(args)
    if socket_path is not None:
        refusal = _refused_by_daemon(args, socket_path)
        if refusal is not None:
            print(refusal, file=sys.stderr)
            return EXIT_REJECTED
        view = _view(args, args.program)
        from controller.operator.run.remote import run_on_daemon  # only a run through cncd

        try:
            return run_on_daemon(args, socket_path, view)
        except DaemonUnavailable as exc:  # no daemon at all: rejected; lost mid-job: a fault
            view.close()
            print(f"cncctl: {exc}" + (" (nothing moved)" if isinstance(exc, NoDaemon) else ""),
                  file=sys.stderr)
            return EXIT_REJECTED if isinstance(exc, NoDaemon) else 3
    try:
        config = config_with_drive_options(load_config(args.config), args.drive_option)
        if args.tools is not None:
            config = replace(config, tools=config.tools.with_table(
                load_tool_table(args.tools, missing_ok=False)))
        offsets = load_offsets(args.offsets, missing_ok=False) \
            if args.offsets is not None else None
        track = ProgramOffsets()
        # The blocks, for the interpreter stage (see _checked_blocks), kept only for a run
        # that can take them: from the start, on the sim card (a probe found only by the
        # check still reads the program again).
        kept = _kept_blocks() if _from_start_on_sim(args, config) else None
        with fewer_collections():  # (runtime/gc_policy.py: the blocks kept are not re-scanned)
            check_program(args.program, config, offsets=offsets, from_line=args.from_line,
                          track=track, summary=False, keep=kept)
    except (NcError, ConfigError, OffsetsError, ToolTableError) as exc:
        print(exc.format() if isinstance(exc, NcError) else str(exc), file=sys.stderr)
        return EXIT_REJECTED
    needs_homing = any(a.homing is not None for a in config.axes) and not config.allow_unhomed
    if needs_homing and not args.home:
        print("cncctl: the axes with a homing sequence are not homed: run with --home (or "
              "through cncd after `cncctl home`); the config's allow_unhomed permits it",
              file=sys.stderr)
        return EXIT_REJECTED
    view = _view(args, args.program)
    options = RuntimeOptions(virtual_time=args.virtual_time, optional_stop=args.optional_stop,
                             offsets=offsets, override_off_lines=track.override_off_lines)
    runtime: Any = Runtime(args.program, config, options)
    # A real drive keeps its position between runs: the program is checked and planned from
    # where it stands (read from the drive opened once for the run), not from X0 Y0, which
    # faulted the second run ("reference starts at 0 but the machine is at 5") or, for a
    # G0 X0 Y0, reported done with nothing moved. The simulated card starts at 0 when opened.
    probing = track.probes.seen  # G38 lines: a stretch per probe (run/probing.py)
    shared_drive = not _from_start_on_sim(args, config) or bool(probing)
    if shared_drive:
        runtime = Sequence()
    keys = KeyControl(runtime, lambda text: print(f"cncctl: {text}", file=sys.stderr,
                                                  flush=True), abort_at_pause_without_keys=True)
    tools = ToolChanges(track.io_events, _event_to(view))
    options = replace(options, on_progress=_Announcer(view.progress, keys, tools).progress,
                      on_event=lambda e: view.event(**e))  # an output changed: a line each
    if not shared_drive and kept is not None:
        runtime.options = _checked_blocks(options, kept)
    fd = stdin_fd()
    restore_terminal: list[Any] = [lambda: None]

    def start_keys() -> None:
        if fd is not None:
            restore_terminal[0] = read_keys(fd, keys.key, keys.closed)
        else:
            keys.closed()  # no standard input at all: nothing can resume an M0
    if not (shared_drive and args.from_line is not None and not args.yes):
        start_keys()  # else once the approach is confirmed (run_from_line)

    def on_stop_signal(signum: int, frame: Any) -> None:
        # Never a silent kill: decelerate along the path, then exit 4. SIGTERM is what systemd
        # and kill send, SIGHUP a closed terminal: both stop like Ctrl-C.
        runtime.request_abort(f"aborted by operator ({signal.Signals(signum).name})")
    previous = {sig: signal.signal(sig, on_stop_signal) for sig in STOP_SIGNALS}
    try:
        if not args.virtual_time:
            _say_scheduling()
        view.event("start", program=args.program, config=config.name,
                   drive=config.drive.backend, virtual_time=args.virtual_time)
        if not shared_drive:
            result = runtime.run()
        elif probing:
            from controller.operator.run.probing import run_probing  # only a probing program

            result = run_probing(args, config, offsets, options, runtime, probing,
                                 _event_to(view))
        else:
            result = run_from_line(args, config, offsets, options, runtime, start_keys)
            if result is None:
                view.close()
                print("cncctl: not confirmed: nothing moved", file=sys.stderr)
                return EXIT_REJECTED
    except DriveUnavailableError as exc:
        view.close()
        print(f"cncctl: {exc} (nothing moved)", file=sys.stderr)
        return EXIT_REJECTED
    except HomingAborted as exc:
        view.close()
        print(f"cncctl: {exc}; the program did not start", file=sys.stderr)
        return EXIT_CODES[Outcome.ABORTED]
    except NcError as exc:
        view.close()
        print(exc.format(), file=sys.stderr)
        return EXIT_REJECTED
    except CncError as exc:
        view.close()
        print(f"cncctl: {exc}", file=sys.stderr)
        return 3
    finally:
        restore_terminal[0]()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    view.close()
    view.final(result)
    return EXIT_CODES[result.outcome]


def _from_start_on_sim(args: argparse.Namespace, config: Any) -> bool:
    return args.from_line is None and not args.home and config.drive.backend == "sim"


def _kept_blocks() -> Any:
    from controller.operator.check_cmd import KEEP_BLOCKS, KEEP_LINES
    from controller.operator.kept_blocks import KeptBlocks

    return KeptBlocks(KEEP_BLOCKS, KEEP_LINES, KEEP_BLOCKS)


def _checked_blocks(options: RuntimeOptions, kept: Any) -> RuntimeOptions:
    """A run of the whole program as checked (the same offsets, from its start): its stages
    read the blocks the check kept, if it kept them all (a longer program is read again)."""
    if kept.full:
        return options
    return replace(options, blocks_fn=checked_blocks(kept))


def _say_scheduling() -> None:
    """Without the privilege of real-time scheduling the run goes on, but the operator is told
    at the start (the result's `scheduling` says it too)."""
    sched = probe_scheduling()
    if not sched.privileged:
        print(f"cncctl: scheduling: {sched.summary()}", file=sys.stderr, flush=True)
