"""`cncctl identify` through cncd: the windows asked of the daemon and shown, the operator's
confirmation, the excitation followed; the report printed and `--output` written here, from
what the daemon sent (the daemon never writes a file a client names)."""

from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

from controller.errors import CncError
from controller.operator.client import DaemonClient, DaemonError, refused_through_daemon
from controller.operator.identify.plan import confirm_start
from controller.operator.identify.report import write_config_text
from controller.operator.identify.result import params_from_wire
from controller.operator.run.exit_codes import EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run.remote import RemoteOperator

# How each final event exits: as embedded (1: moved, but the identified loop is refused).
EXIT_OF = {"done": 0, "refused": 1, "fault": 3, "aborted": 4}
EXIT_FAULT = EXIT_OF["fault"]

# Options of an embedded identify that a daemon cannot honour: it owns the drive and its
# config, runs in real time, and homes through `cncctl home`.
_NOT_THROUGH_DAEMON = (
    ("config", "--config", "the daemon runs with its own config (cncd --config)"),
    ("drive_option", "--drive-option", "the daemon's drive is set in its config"),
    ("virtual_time", "--virtual-time", "the daemon's drive runs in real time"),
    ("home", "--home", "home through the daemon first: `cncctl home`"),
)


def _say(text: str) -> None:
    print(f"cncctl: {text}", file=sys.stderr, flush=True)


def refused_by_daemon(args: argparse.Namespace, socket_path: str) -> str | None:
    """Why this identify cannot go through the daemon as asked (None: it can)."""
    return refused_through_daemon(args, socket_path, _NOT_THROUGH_DAEMON, "identify")


def identify_on_daemon(args: argparse.Namespace, socket_path: str, out: str | None) -> int:
    """Ask the windows, show them, confirm, then start with the positions shown (the daemon
    refuses `moved` if an axis stands elsewhere by then) and follow to the end."""
    fields = {"axes": [a.lower() for a in args.axes], "window_mm": args.window,
              "duration_s": args.duration}
    with DaemonClient(socket_path) as client:
        try:
            windows = client.request("identify", plan_only=True, **fields)["windows"]
        except DaemonError as exc:
            _say(f"the daemon refused identify: {exc.code}: {exc}. Nothing moved")
            return EXIT_REJECTED
    for w in windows:
        _say(w["text"])
    if not confirm_start(args.yes):
        _say("not confirmed: nothing moved")
        return EXIT_REJECTED
    with DaemonClient(socket_path) as client:
        try:
            client.request("identify", follow=True, **fields,
                           from_mm={w["axis"]: w["here_mm"] for w in windows})
        except DaemonError as exc:
            _say(f"the daemon refused identify: {exc.code}: {exc}. Nothing moved")
            return EXIT_REJECTED
        previous = {sig: signal.signal(sig, _abort_on(socket_path)) for sig in STOP_SIGNALS}
        try:
            return _follow(client, out)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)


def _abort_on(socket_path: str) -> Any:
    def handler(signum: int, frame: Any) -> None:
        RemoteOperator(socket_path).request_abort()
    return handler


def _follow(client: DaemonClient, out: str | None) -> int:
    for event in client.messages():
        kind = event.get("event")
        if kind == "axis":
            _say(str(event.get("message", "")))
        elif kind in EXIT_OF:
            if event.get("report"):
                print("\n".join(event["report"]), flush=True)
            if event.get("message"):
                _say(str(event["message"]))
            if kind == "done" and out is not None:
                return _write(event, out)
            return EXIT_OF[kind]
    _say("the daemon hung up before identify ended (see `cncctl status`)")
    return EXIT_FAULT


def _write(event: dict[str, Any], out: str) -> int:
    """--output from the daemon's config text and the identified loops, checked as it is
    written (report.write_config_text loads it back)."""
    if not event.get("config_yaml"):
        _say(f"--output {out}: {event.get('config_note') or 'the daemon sent no config'}")
        return EXIT_FAULT
    try:
        write_config_text(event["config_yaml"], str(event.get("config_name", "cncd")),
                          str(event.get("config_path", "cncd")),
                          params_from_wire(event["fits"]), out)
    except (OSError, CncError, KeyError, TypeError, ValueError) as exc:
        _say(f"--output {out}: {exc}")
        return EXIT_FAULT
    _say(f"wrote {out}")
    return 0
