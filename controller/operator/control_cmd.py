"""`cncctl status | abort | estop | reset | resume | hold | feed | home | jog | log`: the
daemon's state and commands to it."""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import sys
import threading
import time
from typing import Any

from controller.motion.types import Outcome
from controller.operator.client import (
    DaemonClient,
    DaemonError,
    DaemonUnavailable,
    default_socket_path,
    request_estop,
    socket_argument,
)
from controller.operator.io_text import outputs_text
from controller.operator.run.exit_codes import EXIT_CODES, EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run.remote import FINAL_EVENTS, RemoteOperator
from controller.operator.words import axes_text, offsets_table

# The README's exit codes everywhere: 0 done, 2 rejected (nothing moved), 3 fault, 4 aborted.
EXIT_REFUSED = EXIT_REJECTED
EXIT_NO_DAEMON = EXIT_REJECTED  # no daemon answered: nothing moved (it was 3, "fault")
EXIT_FAULT = EXIT_CODES[Outcome.FAULT]
EXIT_ABORTED = EXIT_CODES[Outcome.ABORTED]


def socket_help() -> str:
    here = default_socket_path().replace("%", "%%")
    return f"the daemon's control socket (default: $CNCD_SOCKET, else /run/cncd/cncd.sock; " \
           f"here {here})"


def log_lines(text: str) -> int:
    """-n: how many of the last events, 0..100000 (the daemon's bounds)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if not 0 <= n <= 100_000:
        raise argparse.ArgumentTypeError(f"{n} is not within 0..100000")
    return n


def add_socket_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--socket", default=None, type=socket_argument, help=socket_help())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_socket_argument(parser)
    command = parser.prog.split()[-1]
    if command == "status":
        parser.add_argument("--json", action="store_true", help="one JSON object")
        parser.add_argument("--watch", action="store_true", help="print every change")
    elif command == "home":
        parser.add_argument("axes", nargs="*", help="axis letters (default: every axis with a "
                                                    "homing sequence, in sequence order)")
    elif command == "jog":
        parser.add_argument("move", help="X+10 (incremental, mm), or X+ / X- (continuous, "
                                         "until Enter, Ctrl-C or the time-out)")
        parser.add_argument("--feed", type=float, default=600.0, help="mm/min (default 600)")
        parser.add_argument("--timeout", type=float, default=30.0,
                            help="continuous jog: stop after this many seconds (default 30)")
    elif command == "offset":
        parser.add_argument("action", choices=("show", "set", "select", "clear-g92"))
        parser.add_argument("system", nargs="?", help="G54 .. G59")
        parser.add_argument("values", nargs="*", help="X10 Y-5: origins in machine "
                            "coordinates, or with --here what the current position reads")
        parser.add_argument("--here", action="store_true",
                            help="the current position becomes the system's zero (or reads "
                                 "the values given)")
        parser.add_argument("--json", action="store_true",
                            help="the whole table as JSON (every axis), not a table")
    elif command == "feed":
        parser.add_argument("percent", type=float,
                            help="feed override in %% of the programmed feed, 0-150 "
                                 "(0 holds until raised)")
    elif command == "log":
        parser.add_argument("-n", "--lines", type=log_lines, default=50,
                            help="last events (0-100000, default 50)")
        parser.add_argument("-f", "--follow", action="store_true", help="then follow")


def run(args: argparse.Namespace) -> int:
    path = args.socket if args.socket is not None else default_socket_path()
    try:
        if args.command == "estop":  # the e-stop socket needs no free connection slot
            reply = request_estop(path)
            if reply is not None:
                print(f"cncctl estop: {reply['state']}")
                return 0
        with DaemonClient(path) as client:
            return _COMMANDS[args.command](client, args)
    except DaemonUnavailable as exc:
        print(f"cncctl: {exc} (is cncd running? `systemctl status cncd`)", file=sys.stderr)
        return EXIT_NO_DAEMON
    except DaemonError as exc:
        print(f"cncctl {args.command}: {exc.code}: {exc}", file=sys.stderr)
        return EXIT_REFUSED


def _status(client: DaemonClient, args: argparse.Namespace) -> int:
    reply = client.request("status")
    _print_status(reply, args.json)
    if not args.watch:
        return 0
    client.request("subscribe", topics=["state", "progress"])
    last_s = 0.0
    for event in client.messages():
        if event.get("event") == "progress" and time.monotonic() - last_s < 0.5:
            continue
        last_s = time.monotonic()
        _print_status(client.request("status"), args.json)
    return 0


def _print_status(s: dict[str, Any], as_json: bool) -> None:
    s = {k: v for k, v in s.items() if k not in ("id", "ok")}
    if as_json:
        print(json.dumps(s), flush=True)
        return
    pos = s.get("position_mm") or {}
    where = " ".join(f"{k.upper()}{v:.3f}" for k, v in pos.items()) or "unknown"
    print(f"{s['state']}" + (f": {s['fault']}" if s.get("fault") else ""), flush=True)
    if s.get("program"):
        print(f"  job {s['job']} {s['program']} line {s['line']}  feed "
              f"{s['feed_mm_s']:.1f} mm/s  following error {s['ferror_um']:.0f} um")
    print(f"  feed override {s.get('feed_override_pct', 100.0):g} %")
    if s.get("drives") == "disabled":
        print("  drives disabled (e-stop): `cncctl reset` enables them")
    elif s.get("drives"):
        print("  drives enabled")
    if s.get("estop_input"):
        print("  e-stop input open (tripped): close it, then `cncctl reset`")
    print(f"  position {where}")
    if s.get("outputs"):
        print(f"  outputs: {outputs_text(s['outputs'])}")
    work = s.get("work_position_mm") or {}
    if work:
        system = (s.get("offsets") or {}).get("active", "G54")
        print(f"  work position ({system}) "
              + " ".join(f"{k.upper()}{v:.3f}" for k, v in work.items()))
    homed = s.get("homed") or {}
    if homed and not all(homed.values()):
        print("  not homed: " + " ".join(k.upper() for k, v in homed.items() if not v))
    for problem in s.get("state_problems") or []:
        print(f"  state directory: {problem}", flush=True)
    sched = s.get("scheduling") or {}
    if sched.get("summary"):
        print(f"  scheduling: {sched['summary']}")
    last = s.get("last_job") or {}
    if last.get("program"):
        print(f"  last job {last['program']}: {last.get('state', '?').lower()} at line "
              f"{last.get('last_line')}" + (f" ({last['fault']})" if last.get("fault") else ""),
              flush=True)
        residual = last.get("model_residual_um") or {}
        if residual.get("samples"):
            print(f"  model residual max {residual['max']:.1f} um rms {residual['rms']:.1f} um "
                  "(measured against the servo model)")
        if last.get("model_warning"):
            print(f"  WARNING: {last['model_warning']}", flush=True)
    ident = s.get("last_identify") or {}
    if ident.get("event"):
        fits = ", ".join(f"{k.upper()} {v['fit_pct']:.1f} %" for k, v in
                         (ident.get("fits") or {}).items())
        print(f"  last identify: {ident['event']}" + (f" (held-out fit {fits})" if fits else "")
              + (f": {ident['message']}" if ident.get("message") else ""), flush=True)


def _simple(client: DaemonClient, args: argparse.Namespace) -> int:
    reply = client.request(args.command)
    print(f"cncctl {args.command}: {reply['state']}"
          + (f" ({reply['note']})" if reply.get("note") else ""))
    return 0


HOME_WORD_S = 10.0  # after an e-stop, the homing thread's own word is this late at most


def _home(client: DaemonClient, args: argparse.Namespace) -> int:
    """Home, then say how it ended: 0 done, 3 failed, 4 aborted by an e-stop (it exited 1,
    and printed "None" when an e-stop came before the homing had said its word)."""
    client.request("home", axes=[a.upper() for a in args.axes])
    deadline_s = time.monotonic() + HOME_WORD_S
    while (status := client.request("status"))["state"] == "HOMING" or (
            status.get("last_homing") is None and time.monotonic() < deadline_s):
        time.sleep(0.1)
    homed = status.get("homed", {})
    word = status.get("last_homing") or "ended without a word (see `cncctl log`)"
    print(f"cncctl home: {word}; homed "
          + " ".join(f"{k.upper()}={'yes' if v else 'no'}" for k, v in homed.items()))
    _print_status(status, False)
    if word == "done":
        return 0
    return EXIT_ABORTED if status["state"] == "ESTOP" else EXIT_FAULT


JOG = re.compile(r"^([XYZxyz])([+-])(\d+\.?\d*|\.\d+)?$")


def _jog(client: DaemonClient, args: argparse.Namespace) -> int:
    m = JOG.match(args.move)
    if m is None:
        print(f"cncctl jog: {args.move!r}: expected an axis, a sign and a distance (X+10), or "
              "an axis and a sign (X+: continuous)", file=sys.stderr)
        return EXIT_REFUSED
    axis, sign, number = m.group(1).lower(), 1 if m.group(2) == "+" else -1, m.group(3)
    fields: dict[str, Any] = {"axis": axis, "feed_mm_min": args.feed, "follow": True}
    if number is None:
        fields |= {"direction": sign, "timeout_s": args.timeout}
    else:
        fields["distance_mm"] = sign * float(number)
    reply = client.request("jog", **fields)
    print(f"cncctl jog: {reply['message']}" + (" (Enter or Ctrl-C stops it)"
                                               if number is None else ""), flush=True)
    released = threading.Event()
    if number is None:
        _stop_on_enter(client.path, released)
    return _follow_job(client, continuous=number is None, released=released)


def _stop_on_enter(socket_path: str, released: threading.Event) -> None:
    """A continuous jog ends when released: Enter (or Ctrl-C, handled by _follow_job)."""
    def wait() -> None:
        try:
            fd = sys.stdin.fileno()
            if os.read(fd, 1):
                released.set()
                RemoteOperator(socket_path).request_abort()
        except (OSError, ValueError):
            pass
    threading.Thread(target=wait, daemon=True).start()


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _follow_job(client: DaemonClient, continuous: bool = False,
                released: threading.Event | None = None) -> int:
    """Follow a jog to its end; Ctrl-C, SIGTERM or SIGHUP (a closed terminal) stops it along
    the path (before, the last two left a continuous jog running to its time-out). Exit as a
    run: 0 done, 2 rejected, 3 fault (a jog that moved, then faulted, exited 2: "nothing
    moved"), 4 aborted; a continuous jog released (Enter) or timed out ends as asked: 0."""
    previous = {sig: signal.signal(sig, _interrupt) for sig in STOP_SIGNALS}
    try:
        for event in client.messages():
            kind = event.get("event")
            if kind in FINAL_EVENTS or kind == "rejected":
                where = event.get("final_position_mm")
                message = event.get("message") or ""
                print(f"cncctl: {kind}" + (f": {message}" if message else "")
                      + (f" at {axes_text(where)}" if where else ""))
                if kind == "rejected":
                    return EXIT_REFUSED
                if kind == "aborted" and continuous and (
                        (released is not None and released.is_set())
                        or "jog time-out" in message):
                    return 0
                return FINAL_EVENTS[kind]
    except KeyboardInterrupt:
        RemoteOperator(client.path).request_abort()
        return _follow_job(client)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    print("cncctl: the daemon hung up before the jog ended (see `cncctl status`)",
          file=sys.stderr)
    return EXIT_FAULT


AXIS_VALUE = re.compile(r"^([XYZxyz])([-+]?(\d+\.?\d*|\.\d+))$")


def _offset(client: DaemonClient, args: argparse.Namespace) -> int:
    if args.action == "show":
        table = client.request("status").get("offsets", {})
    else:
        values: dict[str, float] = {}
        for word in args.values:
            m = AXIS_VALUE.match(word)
            if m is None:
                print(f"cncctl offset: {word!r}: expected an axis and a value (X10)",
                      file=sys.stderr)
                return EXIT_REFUSED
            values[m.group(1).lower()] = float(m.group(2))
        table = client.request("offset", action=args.action, system=args.system or "",
                               values=values, here=args.here)["offsets"]
    if args.json:
        print(json.dumps(table, indent=2))
    else:
        print(offsets_table(table, _machine_axes(client)))
    return 0


def _machine_axes(client: DaemonClient) -> list[str]:
    """The machine's axes, as the daemon's status names them (xyz when it names none)."""
    status = client.request("status")
    for key in ("position_mm", "homed", "work_position_mm"):
        if status.get(key):
            return list(status[key])
    return list("xyz")


def _feed(client: DaemonClient, args: argparse.Namespace) -> int:
    reply = client.request("feed", percent=args.percent)
    print(f"cncctl feed: {reply['feed_override_pct']:g} %")
    return 0


def _log(client: DaemonClient, args: argparse.Namespace) -> int:
    reply = client.request("log", lines=args.lines, follow=args.follow)
    for event in reply["events"]:
        _print_event(event)
    if args.follow:
        for event in client.messages():
            if event.get("event") == "log":
                _print_event(event)
    return 0


def _print_event(event: dict[str, Any]) -> None:
    stamp = time.strftime("%H:%M:%S", time.localtime(event["time"]))
    print(f"{stamp} {event['priority']:<7} {event['message']}", flush=True)


_COMMANDS = {"status": _status, "abort": _simple, "estop": _simple, "reset": _simple,
             "resume": _simple, "hold": _simple, "feed": _feed, "home": _home, "jog": _jog,
             "offset": _offset,
             "log": _log}
