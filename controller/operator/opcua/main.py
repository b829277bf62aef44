"""The OPC UA server process cncd starts beside itself (`python -m controller.operator.opcua.main
--config FILE --socket PATH`): the Machine Tools model fed from cncd's control socket, until
SIGTERM or cncd's end."""

from __future__ import annotations

import argparse
import asyncio
import ctypes
import logging
import os
import signal
import sys
from typing import Any

from asyncua import Server, ua

from controller.config import load_config
from controller.errors import CncError
from controller.opcua_config import OpcuaConfig
from controller.operator.opcua.bridge import Bridge
from controller.operator.opcua.methods import PasswordUsers, ReadOnlyRules, add_methods
from controller.operator.opcua.model import build
from controller.operator.opcua.view import View

PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """SIGTERM when cncd ends, however it ends (a SIGKILL too): never a server left behind."""
    parent = os.getppid()
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # cncd was gone before the request took
        os.kill(os.getpid(), signal.SIGTERM)


def _step_aside() -> None:
    """An ordinary process: cncd's socket thread runs at nice -10 and a child inherits it, but
    the server must never compete with a job's interpreter and generator."""
    current = os.getpriority(os.PRIO_PROCESS, 0)
    if current < 0:
        os.setpriority(os.PRIO_PROCESS, 0, 0)


def _floor_publishing(server: Server, min_ms: float) -> None:
    """asyncua grants any publishing interval asked for: a client asking 1 ms would make the
    server publish a thousand times a second. At least min_ms."""
    service = server.iserver.subscription_service
    create = service.create_subscription

    async def create_floored(params: ua.CreateSubscriptionParameters, *args: Any,
                             **kwargs: Any) -> Any:
        params.RequestedPublishingInterval = max(min_ms, params.RequestedPublishingInterval)
        return await create(params, *args, **kwargs)

    service.create_subscription = create_floored  # type: ignore[method-assign]


async def make_server(cfg: OpcuaConfig, axes: tuple[str, ...], socket_path: str,
                      machine: str) -> tuple[Server, View]:
    # Our user manager always: asyncua's default lets a user named admin write anything.
    server = Server(user_manager=PasswordUsers(cfg.users_file if cfg.methods else None))
    server.iserver.allow_remote_admin = False
    await server.init()
    server.set_endpoint(cfg.endpoint)
    server.set_server_name(f"phcnc {machine}")
    await server.set_application_uri(f"urn:phcnc:{cfg.machine_name}")
    policies = [ua.SecurityPolicyType.NoSecurity]  # anonymous dashboards read in the clear
    if cfg.certificate is not None and cfg.private_key is not None:
        # Also an encrypted endpoint; and on the open one a user's password is encrypted with
        # this certificate rather than sent as it is.
        await server.load_certificate(cfg.certificate)
        await server.load_private_key(cfg.private_key)
        policies.append(ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt)
    server.set_security_policy(policies, permission_ruleset=ReadOnlyRules())
    if cfg.methods:
        server.set_identity_tokens([ua.AnonymousIdentityToken, ua.UserNameIdentityToken])
    else:
        server.set_identity_tokens([ua.AnonymousIdentityToken])
    _floor_publishing(server, cfg.min_publish_ms)
    model = await build(server, cfg.machine_name, axes)
    if cfg.methods:
        assert model.channel is not None
        await add_methods(server, model.channel, model.ns["OWN"], socket_path)
    view = View(model, cfg, axes)
    await view.start()
    return server, view


async def serve(cfg: OpcuaConfig, axes: tuple[str, ...], socket_path: str,
                machine: str) -> None:
    server, view = await make_server(cfg, axes, socket_path, machine)
    async with server:
        # Only now: a SIGTERM while the model is built ends the process at once (nothing is
        # held yet), where a handler would wait for the build to finish.
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop.set)
        logging.getLogger("phcnc.opcua").warning("OPC UA server on %s (%s)", cfg.endpoint,
                                                 "methods for users" if cfg.methods
                                                 else "read-only")
        await Bridge(socket_path, view).run(stop)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="cncd-opcua", description="cncd's OPC UA server")
    ap.add_argument("--config", required=True)
    ap.add_argument("--socket", required=True)
    args = ap.parse_args(argv)
    _die_with_parent()
    _step_aside()
    # journald's format on stderr, as cncd's own lines; asyncua's chatter only from warnings.
    logging.basicConfig(stream=sys.stderr, level=logging.WARNING,
                        format="<4>opcua: %(message)s")
    try:
        config = load_config(args.config)
    except CncError as exc:
        print(f"<3>opcua: {exc}", file=sys.stderr)
        return 2
    cfg = config.service.opcua
    if cfg is None:
        print("<3>opcua: the config has no service.opcua section", file=sys.stderr)
        return 2
    try:
        asyncio.run(serve(cfg, config.axis_names, args.socket, config.name))
    except (CncError, OSError) as exc:
        print(f"<3>opcua: cannot serve {cfg.endpoint}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
