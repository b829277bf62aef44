"""The API's methods, one table for JSON-RPC 2.0 over the WebSocket and POST /api/rpc: each
checks its parameters, then goes through the control socket (the daemon checks again and
refuses as it refuses cncctl), the program library or the job queue."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from controller.config import MachineConfig
from controller.operator.client import (
    DaemonError,
    DaemonUnavailable,
    request_estop,
)
from controller.operator.web.bridge import Bridge
from controller.operator.web.jobs import Jobs
from controller.operator.web.library import Library, LibraryError
from controller.operator.web.mdi import MdiError
from controller.operator.web.preview import program_preview

INVALID_REQUEST, NOT_FOUND, INVALID_PARAMS, INTERNAL = -32600, -32601, -32602, -32603
REFUSED = -32000  # the daemon, the library or the queue said no; data.code says why
UNAVAILABLE = -32001  # the daemon is not answering


class RpcError(Exception):
    def __init__(self, code: int, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.code, self.message, self.reason = code, message, reason

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"code": self.code, "message": self.message}
        if self.reason:
            out["data"] = {"reason": self.reason}
        return out


@dataclass
class Api:
    """What every method may use; `owner` is the caller (one WebSocket or one HTTP request)
    that holds a continuous jog's lease."""

    bridge: Bridge
    jobs: Jobs
    library: Library
    config: MachineConfig


Handler = Callable[[Api, dict[str, Any], object], Awaitable[Any]]
METHODS: dict[str, tuple[Handler, frozenset[str], str]] = {}


def method(name: str, params: tuple[str, ...], doc: str) -> Callable[[Handler], Handler]:
    def register(fn: Handler) -> Handler:
        METHODS[name] = (fn, frozenset(params), doc)
        return fn
    return register


async def call(api: Api, name: Any, params: Any, owner: object) -> Any:
    """One method call; RpcError for anything refused (nothing changed then)."""
    if not isinstance(name, str) or name not in METHODS:
        raise RpcError(NOT_FOUND, "unknown method; see GET /api/openapi.json or docs/api.md")
    params = {} if params is None else params
    if not isinstance(params, dict):
        raise RpcError(INVALID_PARAMS, "params must be an object")
    handler, allowed, _ = METHODS[name]
    extra = set(params) - allowed
    if extra:
        raise RpcError(INVALID_PARAMS, f"{name} takes no parameter {sorted(extra)[0][:32]!r}")
    try:
        return await handler(api, params, owner)
    except DaemonError as exc:
        raise RpcError(REFUSED, str(exc), exc.code) from None
    except LibraryError as exc:
        raise RpcError(REFUSED, exc.message, exc.code) from None
    except MdiError as exc:
        raise RpcError(INVALID_PARAMS, str(exc)) from None
    except DaemonUnavailable as exc:
        raise RpcError(UNAVAILABLE, str(exc), "unavailable") from None


def _plain(cmd: str, doc: str) -> None:
    async def handler(api: Api, params: dict[str, Any], owner: object) -> Any:
        return await _daemon(api, cmd)
    method(cmd, (), doc)(handler)


async def _daemon(api: Api, cmd: str, **fields: Any) -> dict[str, Any]:
    reply = await api.bridge.request(cmd, **fields)
    return {k: v for k, v in reply.items() if k not in ("id", "ok")}


_plain("hold", "feed hold: the job decelerates along the path and waits for resume")
_plain("resume", "continue after a hold or an M0")
_plain("abort", "stop the job along the path")
_plain("reset", "clear a latched e-stop or fault and enable the drives")


@method("auth", ("token",), "the WebSocket's first message when a token is configured; "
                           "accepted as it is without one")
async def _auth(api: Api, params: dict[str, Any], owner: object) -> Any:
    return {"authenticated": True}  # with a token, app.py checked it before any call


@method("status", (), "the last pushed status (state, line, positions, feed, override, ...)")
async def _status(api: Api, params: dict[str, Any], owner: object) -> Any:
    return api.bridge.status


@method("estop", (), "e-stop through the daemon's e-stop socket (latched until reset)")
async def _estop(api: Api, params: dict[str, Any], owner: object) -> Any:
    reply = await asyncio.to_thread(request_estop, api.bridge.socket_path)
    if reply is None:  # a daemon without an e-stop socket: the control socket's estop
        return await _daemon(api, "estop")
    return {"state": reply.get("state")}


@method("feed", ("percent",), "feed override 0-150 %")
async def _feed(api: Api, params: dict[str, Any], owner: object) -> Any:
    return await _daemon(api, "feed", **params)


@method("home", ("axes",), "home the axes (default: every axis with a homing sequence)")
async def _home(api: Api, params: dict[str, Any], owner: object) -> Any:
    return await _daemon(api, "home", **params)


@method("jog", ("axis", "distance_mm", "direction", "feed_mm_min"),
        "jog one axis: distance_mm (incremental) or direction -1/1 (continuous, held by a "
        "lease: renew with jog_renew every 0.2 s; stopped by jog_stop, the lease running out "
        "or the connection closing)")
async def _jog(api: Api, params: dict[str, Any], owner: object) -> Any:
    if "direction" in params and owner is None:
        raise RpcError(INVALID_PARAMS, "a continuous jog needs the WebSocket (it is held "
                                       "while the connection lives)")
    return await api.jobs.jog(owner, params)


@method("jog_renew", (), "keep this connection's continuous jog going for 0.5 s more")
async def _jog_renew(api: Api, params: dict[str, Any], owner: object) -> Any:
    return {"renewed": api.jobs.renew(owner)}


@method("jog_stop", (), "stop this connection's continuous jog")
async def _jog_stop(api: Api, params: dict[str, Any], owner: object) -> Any:
    return {"stopped": await api.jobs.jog_stop(owner)}


@method("offset", ("action", "system", "values", "here"), "work offsets: set, select, clear-g92")
async def _offset(api: Api, params: dict[str, Any], owner: object) -> Any:
    return await _daemon(api, "offset", **params)


@method("log", ("lines",), "the daemon's last events")
async def _log(api: Api, params: dict[str, Any], owner: object) -> Any:
    return await _daemon(api, "log", **params)


@method("run", ("name",), "run a library program as a job (checked whole before motion)")
async def _run(api: Api, params: dict[str, Any], owner: object) -> Any:
    name = params.get("name")
    return await api.jobs.run(str(name), api.library.read(name))


@method("mdi", ("text",), "run one or a few G-code lines as a job; modes kept between them")
async def _mdi(api: Api, params: dict[str, Any], owner: object) -> Any:
    return await api.jobs.mdi(params.get("text"))


@method("programs.list", (), "the library's programs (name, bytes, modified)")
async def _list(api: Api, params: dict[str, Any], owner: object) -> Any:
    return {"programs": api.library.list()}


@method("programs.read", ("name",), "a program's text")
async def _read(api: Api, params: dict[str, Any], owner: object) -> Any:
    return {"name": params.get("name"),
            "text": api.library.read(params.get("name")).decode("utf-8", "replace")}


@method("programs.upload", ("name", "text"), "store a program (up to 1 MiB here; larger "
                                             "through POST /api/programs/NAME)")
async def _upload(api: Api, params: dict[str, Any], owner: object) -> Any:
    text = params.get("text")
    if not isinstance(text, str):
        raise RpcError(INVALID_PARAMS, "text must be the program's text")
    return api.library.write(params.get("name"), text.encode())


@method("programs.delete", ("name",), "delete a program")
async def _delete(api: Api, params: dict[str, Any], owner: object) -> Any:
    api.library.delete(params.get("name"))
    return {"deleted": params.get("name")}


@method("programs.preview", ("name",), "the program's path (lines, arcs, NURBS sampled) in "
                                       "its work frame, each piece with its source line")
async def _preview(api: Api, params: dict[str, Any], owner: object) -> Any:
    path = api.library.path(params.get("name"))
    preview = await asyncio.to_thread(program_preview, path, api.config)
    return preview.as_dict()


@method("queue.list", (), "the job queue")
async def _queue(api: Api, params: dict[str, Any], owner: object) -> Any:
    return {"queue": api.jobs.queue}


@method("queue.add", ("name",), "add a library program to the end of the queue")
async def _queue_add(api: Api, params: dict[str, Any], owner: object) -> Any:
    return api.jobs.enqueue(params.get("name"))  # type: ignore[arg-type]


@method("queue.remove", ("id",), "remove a queue entry that is not running")
async def _queue_remove(api: Api, params: dict[str, Any], owner: object) -> Any:
    api.jobs.remove(params.get("id"))  # type: ignore[arg-type]
    return {"queue": api.jobs.queue}


@method("queue.start_next", (), "start the first queued job (each job is started by hand)")
async def _queue_next(api: Api, params: dict[str, Any], owner: object) -> Any:
    return await api.jobs.start_next()


@method("queue.clear_finished", (), "drop the entries that have ended")
async def _queue_clear(api: Api, params: dict[str, Any], owner: object) -> Any:
    api.jobs.clear_finished()
    return {"queue": api.jobs.queue}


async def answer(api: Api, message: Any, owner: object) -> dict[str, Any] | None:
    """One JSON-RPC 2.0 request object -> its response (None for a notification)."""
    if not isinstance(message, dict) or message.get("jsonrpc") != "2.0":
        return _error(None, RpcError(INVALID_REQUEST, "a JSON-RPC 2.0 request object"))
    rid = message.get("id")
    if rid is not None and (isinstance(rid, bool) or not isinstance(rid, int | str)
                            or isinstance(rid, str) and len(rid) > 64):
        return _error(None, RpcError(INVALID_REQUEST, "id: an integer or a short text"))
    try:
        result = await call(api, message.get("method"), message.get("params"), owner)
    except RpcError as exc:
        return _error(rid, exc) if "id" in message else None
    return {"jsonrpc": "2.0", "id": rid, "result": result} if "id" in message else None


def _error(rid: Any, exc: RpcError) -> dict[str, Any]:
    return {"jsonrpc": "2.0", "id": rid, "error": exc.as_dict()}
