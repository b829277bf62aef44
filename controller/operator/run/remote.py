"""`cncctl run` through cncd: the program text goes over the socket, events come back into
the same views as an embedded run; a stop signal asks the daemon to abort."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path
from typing import Any

from controller.io_events import EVENT_KINDS
from controller.operator.client import (
    DaemonClient,
    DaemonError,
    DaemonUnavailable,
    NoDaemon,
    daemon_answers,
)
from controller.operator.daemon.protocol import MAX_PROGRAM_BYTES
from controller.operator.run.exit_codes import EXIT_CODES, EXIT_REJECTED, STOP_SIGNALS
from controller.operator.run.from_line import confirm
from controller.operator.run.keys import KeyControl, read_keys, stdin_fd
from controller.operator.run.view import progress_from_event

FINAL_EVENTS = {outcome.value: code for outcome, code in EXIT_CODES.items()}


def run_on_daemon(args: argparse.Namespace, socket_path: str, view: Any) -> int:
    try:
        text = _program_text(args.program)
    except (OSError, ValueError) as exc:  # as the embedded run and `check` say it
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        print(f"{args.program}:0:0: error: cannot open program: {reason}", file=sys.stderr)
        return EXIT_REJECTED
    from_line = getattr(args, "from_line", None)
    if from_line is not None:
        if not daemon_answers(socket_path):  # no question about a motion that cannot happen
            raise NoDaemon(f"no daemon answers on {socket_path}")
        if not confirm(args, f"cncctl: run from line {from_line}: the machine first moves in "
                             "a straight line to where the program stands there"):
            print("cncctl: not confirmed: nothing moved", file=sys.stderr)
            return EXIT_REJECTED
    with DaemonClient(socket_path) as client:
        try:
            client.request("run", payload=text, name=args.program[-255:],
                           program_bytes=len(text), follow=True,
                           optional_stop=bool(getattr(args, "optional_stop", False)),
                           **({"from_line": from_line} if from_line is not None else {}))
        except DaemonError as exc:
            print(f"cncctl: the daemon refused the job: {exc.code}: {exc}", file=sys.stderr)
            return EXIT_REJECTED
        previous = {sig: signal.signal(sig, _abort_on(socket_path)) for sig in STOP_SIGNALS}
        keys = KeyControl(RemoteOperator(socket_path),
                          lambda text: print(f"cncctl: {text}", file=sys.stderr, flush=True))
        fd = stdin_fd()
        restore_terminal = read_keys(fd, keys.key) if fd is not None else (lambda: None)
        try:
            return _follow(client, view, keys)
        finally:
            restore_terminal()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            view.close()


def _program_text(path: str) -> bytes:
    size = os.path.getsize(path)
    if size > MAX_PROGRAM_BYTES:
        raise ValueError(f"larger than the daemon accepts ({MAX_PROGRAM_BYTES} bytes)")
    return Path(path).read_bytes()


class RemoteOperator:
    """Hold, resume and override of the daemon's job, each on a connection of its own (the
    run's connection is busy reading events); a refusal (nothing to resume) is not an error."""

    def __init__(self, socket_path: str) -> None:
        self.socket_path = socket_path

    def _ask(self, cmd: str, **fields: Any) -> None:
        try:
            with DaemonClient(self.socket_path) as other:
                other.request(cmd, **fields)
        except (DaemonError, DaemonUnavailable):
            pass

    def request_hold(self) -> None:
        self._ask("hold")

    def request_resume(self) -> None:
        self._ask("resume")

    def set_feed_override(self, percent: float) -> None:
        self._ask("feed", percent=percent)

    def request_abort(self) -> None:
        self._ask("abort")


def _abort_on(socket_path: str) -> Any:
    def handler(signum: int, frame: Any) -> None:
        RemoteOperator(socket_path).request_abort()
    return handler


def _follow(client: DaemonClient, view: Any, keys: KeyControl) -> int:
    for event in client.messages():
        kind = event.get("event")
        if kind == "rejected":
            view.close()
            print(event["message"], file=sys.stderr)
            return EXIT_REJECTED
        if kind == "start":
            view.event("start", **{k: v for k, v in event.items() if k != "event"})
        elif kind in EVENT_KINDS:  # outputs, tool changes, probes (controller/io_events.py)
            view.event(kind, **{k: v for k, v in event.items() if k != "event"})
        elif kind == "progress":
            p = progress_from_event(event)
            keys.progress(p)
            view.progress(p)
        elif "t_s" in event:  # a job event (an output changed) at a motion time and line
            view.event(**event)
        elif kind in FINAL_EVENTS:
            if "motion_time_s" in event:
                view.final_summary(event)
            else:
                print(f"cncctl: {kind}: {event.get('message', '')}", file=sys.stderr)
            return FINAL_EVENTS[kind]
    print("cncctl: the daemon hung up before the job ended (see `cncctl status`)",
          file=sys.stderr)
    return 3
