"""`cncctl simdrive BACKEND`: a simulated drive peer in its own process, on a pseudo-terminal.

Prints the device path the controller should open as its first line of standard output, then
serves until SIGTERM or SIGINT (exit 0). For tests and for trying a config without hardware:

    cncctl simdrive canopen          # -> /dev/pts/7
    cncctl run nc_programs/naca2415.nc --config canopen --drive-option channel=/dev/pts/7
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from controller.config import load_config
from controller.errors import CncError, ConfigError
from controller.operator.drive_args import parse_drive_options


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("backend", choices=("canopen", "serial"), help="wire protocol to speak")
    parser.add_argument("--config", help="machine configuration (default: the backend's "
                                         "built-in config, canopen or serial)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="simulator option (repeatable), e.g. drive_fault_after_s=0.5")


_announced: list[str] = []  # the device path, once the peer serves on it


def _announce(path: str) -> None:
    _announced.append(path)
    print(path, flush=True)


def run(args: argparse.Namespace) -> int:
    from drivers.errors import DriveUnavailableError
    from drivers.registry import simulated_peer  # late: only this backend's libraries load

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, lambda *_: stop.set())
    try:
        config = load_config(args.config or args.backend)
        serve = simulated_peer(args.backend)
        serve(config, parse_drive_options(args.option), _announce, stop)
    except ConfigError as exc:
        print(f"cncctl simdrive: config error: {exc}", file=sys.stderr)
        return 2
    except DriveUnavailableError as exc:  # a bad plant option: refused before the pty opens
        print(f"cncctl simdrive: {exc}", file=sys.stderr)
        return 2
    except CncError as exc:
        print(f"cncctl simdrive: {exc}", file=sys.stderr)
        # Refused before it served (a bad option: no device was printed) is 2, as everywhere;
        # a failure while serving is 3.
        return 3 if _announced else 2
    return 0
