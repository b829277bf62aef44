"""`cncctl run` through cncd: the program text goes over the socket, events come back into
the same views as an embedded run; a stop signal asks the daemon to abort."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path
from typing import Any

from controller.operator.client import DaemonClient, DaemonError, DaemonUnavailable
from controller.operator.daemon.protocol import MAX_PROGRAM_BYTES
from controller.operator.run_exit import EXIT_CODES, EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run_view import progress_from_event

FINAL_EVENTS = {outcome.value: code for outcome, code in EXIT_CODES.items()}


def run_on_daemon(args: argparse.Namespace, socket_path: str, view: Any) -> int:
    try:
        text = _program_text(args.program)
    except (OSError, ValueError) as exc:
        print(f"cncctl: {args.program}: {exc}", file=sys.stderr)
        return EXIT_REJECTED
    with DaemonClient(socket_path) as client:
        try:
            client.request("run", payload=text, name=args.program[-255:],
                           program_bytes=len(text), follow=True)
        except DaemonError as exc:
            print(f"cncctl: the daemon refused the job: {exc.code}: {exc}", file=sys.stderr)
            return EXIT_REJECTED
        previous = {sig: signal.signal(sig, _abort_on(socket_path)) for sig in STOP_SIGNALS}
        try:
            return _follow(client, view)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            view.close()


def _program_text(path: str) -> bytes:
    size = os.path.getsize(path)
    if size > MAX_PROGRAM_BYTES:
        raise ValueError(f"larger than the daemon accepts ({MAX_PROGRAM_BYTES} bytes)")
    return Path(path).read_bytes()


def _abort_on(socket_path: str) -> Any:
    def handler(signum: int, frame: Any) -> None:
        # On a second connection: the first one is busy reading events.
        try:
            with DaemonClient(socket_path) as other:
                other.request("abort")
        except (DaemonError, DaemonUnavailable):
            pass
    return handler


def _follow(client: DaemonClient, view: Any) -> int:
    for event in client.messages():
        kind = event.get("event")
        if kind == "rejected":
            view.close()
            print(event["message"], file=sys.stderr)
            return EXIT_REJECTED
        if kind == "start":
            view.event("start", **{k: v for k, v in event.items() if k != "event"})
        elif kind == "progress":
            view.progress(progress_from_event(event))
        elif kind in FINAL_EVENTS:
            if "motion_time_s" in event:
                view.final_summary(event)
            else:
                print(f"cncctl: {kind}: {event.get('message', '')}", file=sys.stderr)
            return FINAL_EVENTS[kind]
    print("cncctl: the daemon hung up before the job ended (see `cncctl status`)",
          file=sys.stderr)
    return 3
