"""Hold, Resume and Abort on the channel, only when `service.opcua.methods` is on, only for a
user the users file authenticates, and only as requests on cncd's control socket: the socket
checks them as it checks `cncctl hold`, `resume` and `abort`, so there is no other way in."""

from __future__ import annotations

import asyncio
import contextvars
import json
import logging
from typing import Any

from asyncua import Node, Server, ua
from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, User, UserRole
from asyncua.server.internal_session import InternalSession

from controller.operator.opcua.users import check_password, read_users

log = logging.getLogger("phcnc.opcua")
METHODS = {"Hold": "hold", "Resume": "resume", "Abort": "abort"}
REPLY_TIMEOUT_S = 5.0
# The user of the session whose Call is being served. asyncua hands a method only its object
# and arguments; its sessions serve each request in their own task, so a context variable set
# around InternalSession.call is seen by the method and by no other session.
CALLER: contextvars.ContextVar[User | None] = contextvars.ContextVar("caller", default=None)


class OperatorUser(User):
    """An authenticated user: may call the methods, never write (asyncua writes are Admin's)."""

    def __init__(self, name: str) -> None:
        super().__init__(role=UserRole.User, name=name)


WRITE = ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)


class ReadOnlyRules(PermissionRuleset):
    """What a session may ask: everyone reads, browses and subscribes; nobody writes (no
    session is ever Admin); only an authenticated user calls a method."""

    def __init__(self) -> None:
        read = {ua.NodeId(t) for t in USER_TYPES} - {WRITE, CALL}
        self.allowed = {UserRole.Anonymous: read, UserRole.User: read | {CALL}}

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        return action_type_id in self.allowed.get(user.role, set())


class PasswordUsers:
    """asyncua's user manager: anonymous sessions read; a name and password from the users
    file (read again at each log-in, so a removed user is out at once) call the methods."""

    def __init__(self, users_file: str | None) -> None:
        self.users_file = users_file  # None: read-only, nobody logs in
        if users_file is not None:
            read_users(users_file)  # refused at start-up, not at the first log-in

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        # Only anonymous and user-name tokens are offered (make_server): the channel's own
        # certificate, if the client sent one, says nothing about the user.
        if username is None:
            return User(role=UserRole.Anonymous)
        if self.users_file is None:
            return None
        try:
            stored = read_users(self.users_file).get(username)
        except Exception as exc:  # noqa: BLE001  (a bad file refuses everyone, logged)
            log.error("users file: %s", exc)
            return None
        if stored is None or password is None or not check_password(password, stored):
            log.warning("OPC UA log-in refused for %r", username[:64])
            return None
        return OperatorUser(username)


def _patch_call() -> None:
    if getattr(InternalSession.call, "_phcnc", False):
        return
    original = InternalSession.call

    async def call(self: InternalSession, params: list[ua.CallMethodRequest]) -> Any:
        token = CALLER.set(self.user)
        try:
            return await original(self, params)
        finally:
            CALLER.reset(token)

    call._phcnc = True  # type: ignore[attr-defined]
    InternalSession.call = call  # type: ignore[method-assign]


async def add_methods(server: Server, channel: Node, ns: int, socket_path: str) -> None:
    _patch_call()
    for name, cmd in METHODS.items():
        await channel.add_method(ua.NodeId(0, ns), ua.QualifiedName(name, ns),
                                 _method(cmd, socket_path), [], [ua.VariantType.String])


def _method(cmd: str, socket_path: str) -> Any:
    async def method(parent: ua.NodeId) -> Any:
        user = CALLER.get()
        if not isinstance(user, OperatorUser):
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        reply = await request(socket_path, cmd)
        log.warning("OPC UA user %r: %s -> %s", user.name, cmd,
                    reply.get("state") if reply.get("ok") else reply.get("error"))
        if not reply.get("ok"):
            return ua.StatusCode(ua.StatusCodes.BadInvalidState)
        return [ua.Variant(str(reply.get("state", "")), ua.VariantType.String)]
    return method


async def request(socket_path: str, cmd: str) -> dict[str, Any]:
    """One request on a connection of its own, as cncctl sends it; its reply."""
    try:
        reader, writer = await asyncio.open_unix_connection(socket_path)
    except OSError as exc:
        return {"ok": False, "error": "no-daemon", "message": str(exc)}
    try:
        writer.write(json.dumps({"id": 1, "cmd": cmd}).encode() + b"\n")
        await writer.drain()
        while True:
            line = await asyncio.wait_for(reader.readline(), REPLY_TIMEOUT_S)
            if not line:
                return {"ok": False, "error": "closed"}
            msg = json.loads(line)
            if "ok" in msg:
                return msg
    except (OSError, TimeoutError, ValueError) as exc:
        return {"ok": False, "error": "connection", "message": str(exc)}
    finally:
        writer.close()
