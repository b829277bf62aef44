"""`python -m controller.operator.web.main`: the web panel's process, which cncd starts with
`--http HOST:PORT` (or `service.http`) and stops with itself. It serves until the daemon
hangs up, SIGTERM, or its parent (cncd) dies."""

from __future__ import annotations

import argparse
import asyncio
import ctypes
import os
import signal
import sys
from pathlib import Path

from controller.config import load_config
from controller.errors import CncError
from controller.http_listen import ListenError, is_loopback, parse_listen
from controller.operator.client import DaemonUnavailable
from controller.operator.web import guard
from controller.operator.web.library import Library, LibraryError
from controller.operator.web.mdi import MdiSession

PR_SET_PDEATHSIG = 1
EXIT_REFUSED = 2  # cncd then refuses to start as well (a panel asked for and not served)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cncd-web", description="phcnc web panel and API")
    ap.add_argument("--socket", required=True, help="cncd's control socket")
    ap.add_argument("--listen", required=True, help="HOST:PORT (127.0.0.1 by default)")
    ap.add_argument("--state-dir", required=True, help="the program library's parent")
    ap.add_argument("--config", help="the daemon's config (for previews and MDI)")
    ap.add_argument("--token-file", help="the API token (needed beyond the loopback)")
    ap.add_argument("--parent-pid", type=int, help="stop when this process is gone")
    return ap


def _die_with_parent(parent_pid: int | None) -> None:
    """SIGTERM when cncd dies, even by SIGKILL: a panel must never outlive its daemon."""
    if parent_pid is None:
        return
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent_pid:  # it died before prctl
        raise SystemExit(1)


def _ordinary_priority() -> None:
    """The panel inherits nice -10 from cncd's socket thread: back to 0, below the socket
    loop and a job's interpreter and generator, which it must never hold up."""
    if os.getpriority(os.PRIO_PROCESS, 0) < 0:
        os.setpriority(os.PRIO_PROCESS, 0, 0)


def settings(args: argparse.Namespace) -> tuple[str, int, str | None]:
    """(host, port, token); SystemExit naming the problem when the panel may not start."""
    try:
        host, port = parse_listen(args.listen)
    except ListenError as exc:
        raise SystemExit(f"cncd-web: --http {args.listen!r}: {exc}") from None
    token = None
    if args.token_file:
        try:
            token = guard.read_token(args.token_file)
        except guard.TokenError as exc:
            raise SystemExit(f"cncd-web: token: {exc}") from None
    if token is None and not is_loopback(host):
        raise SystemExit(f"cncd-web: refused to listen on {host}: beyond the loopback the "
                         "API needs a token (service.http_token_file or --http-token-file)")
    return host, port, token


async def serve(args: argparse.Namespace, host: str, port: int, token: str | None) -> int:
    from aiohttp import web

    from controller.operator.web.app import app_watched, distribute, make_app
    from controller.operator.web.bridge import Bridge
    from controller.operator.web.jobs import Jobs
    from controller.operator.web.rpc import Api

    config = load_config(args.config)
    library = Library(Path(args.state_dir))
    bridge = Bridge(args.socket, config.axis_names)
    await bridge.start()
    app_holder: list[web.Application] = []
    notify = lambda kind, message: distribute(app_holder[0], kind, message)  # noqa: E731
    jobs = Jobs(bridge, library, MdiSession(config), notify)
    app = make_app(Api(bridge, jobs, library, config), token)
    app_holder.append(app)
    bridge.watched = lambda: app_watched(app)
    bridge.listeners.add(notify)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port, reuse_address=True)
    await site.start()
    print(f"<5>web panel on http://{host}:{port}/ ({'token' if token else 'no token'})",
          file=sys.stderr, flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    gone = asyncio.create_task(bridge.gone())
    stopped = asyncio.create_task(stop.wait())
    await asyncio.wait({gone, stopped}, return_when=asyncio.FIRST_COMPLETED)
    await jobs.close()
    await runner.cleanup()
    await bridge.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _die_with_parent(args.parent_pid)
    _ordinary_priority()
    host, port, token = settings(args)
    try:
        return asyncio.run(serve(args, host, port, token))
    except (CncError, LibraryError, DaemonUnavailable, OSError) as exc:
        print(f"<3>cncd-web: cannot serve: {exc}", file=sys.stderr)
        return EXIT_REFUSED


if __name__ == "__main__":
    raise SystemExit(main())
