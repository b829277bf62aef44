"""`cncctl`: the operator command (check, inspect, simulate, run, the daemon's commands)."""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys

from controller import __version__

# (sub-command, module providing add_arguments(parser) and run(args) -> exit code, help)
_OPS = "controller.operator."
COMMANDS: tuple[tuple[str, str, str], ...] = (
    ("check", _OPS + "check_cmd", "check a program without moving anything"),
    ("inspect", _OPS + "inspect_cmd", "show NURBS blocks, sharp corners and PH segments"),
    ("simulate", _OPS + "simulate_cmd", "plan a program headless and report its errors"),
    ("run", _OPS + "run.command", "run a program on the configured drive (sim card by default)"),
    ("identify", _OPS + "identify.command",
     "excite the axes, fit their servo loops (eq. 27) and show them beside the model in force"),
    ("status", _OPS + "control_cmd", "the daemon's state, job, position and last job"),
    ("abort", _OPS + "control_cmd", "stop the daemon's running job along the path"),
    ("estop", _OPS + "control_cmd", "e-stop: stop now and latch until reset"),
    ("reset", _OPS + "control_cmd", "clear a latched e-stop or fault"),
    ("resume", _OPS + "control_cmd", "continue the daemon's job after a pause (M0) or a hold"),
    ("hold", _OPS + "control_cmd", "feed hold: decelerate along the path and wait for resume"),
    ("feed", _OPS + "control_cmd", "feed override in % (0-150) of the daemon's jobs"),
    ("home", _OPS + "control_cmd", "home the axes (switches or index, run by the drive)"),
    ("jog", _OPS + "control_cmd", "jog an axis within the soft limits: X+10, or X+ continuous"),
    ("offset", _OPS + "control_cmd", "work offsets: show, set G54 --here, select G55, clear-g92"),
    ("tool", _OPS + "tool_cmd", "the tool table (tool.tbl): list, set T3 Z12.5 D6, delete T3"),
    ("log", _OPS + "control_cmd", "the daemon's last events"),
    ("simdrive", _OPS + "simdrive_cmd", "serve a simulated CANopen drive set or serial card"),
    ("completion", _OPS + "completion_cmd", "print the shell completion script (bash or zsh)"),
)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only the chosen command's module is imported (none given: all of them).

    Importing every command costs about 0.1 s more, which `cncctl run` would pay before the
    first motion."""
    parser = argparse.ArgumentParser(prog="cncctl", description="phcnc CNC controller")
    parser.add_argument("--version", action="version", version=f"cncctl {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    known = {name for name, _, _ in COMMANDS}
    for name, module_name, help_text in COMMANDS:
        # help= is %-formatted by argparse (description is not): "in % (0-150)" crashed --help.
        p = sub.add_parser(name, help=help_text.replace("%", "%%"), description=help_text)
        if command in known and name != command:
            continue
        module = importlib.import_module(module_name)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def _raise_priority_for_motion(argv: list[str]) -> None:
    """`cncctl run` becomes the motion process: outrank ordinary load from the start, so the
    imports and the pre-motion check do not stretch the time to first motion (best effort:
    refused without CAP_SYS_NICE or a LimitNICE, which only costs that time)."""
    if "run" in argv[:1]:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, -10)  # absolute: cncctl run under nice stays -10
        except OSError:
            pass


def main(argv: list[str] | None = None) -> int:
    words = sys.argv[1:] if argv is None else argv
    _raise_priority_for_motion(words)
    args = build_parser(words[0] if words else None).parse_args(argv)
    try:
        return int(args._run(args))
    except KeyboardInterrupt:
        print("cncctl: interrupted", file=sys.stderr)
        return 4
    except BrokenPipeError:
        # The reader went away (`cncctl check PROG | head`): no traceback, and no second
        # error when Python flushes stdout at exit.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    finally:
        if argv is None:  # the process exits next (cncctl itself, not a caller in-process):
            gc.freeze()  # its objects are freed by the exit, not all scanned by a last
            # collection first (some 40 ms of CPU, with numpy and the planner imported)


if __name__ == "__main__":
    sys.exit(main())
