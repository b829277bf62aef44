"""The HTTP and WebSocket server (aiohttp): the panel's files at `/`, `GET /api/status`,
program uploads and the library over plain HTTP, JSON-RPC 2.0 at `POST /api/rpc` and on the
WebSocket `/ws`, which also pushes the status at 25 Hz, the log, job events and the queue."""

from __future__ import annotations

import asyncio
import json
import time
from collections import deque
from importlib import resources
from typing import Any

from aiohttp import WSMsgType, web

from controller.operator.client import DaemonError, DaemonUnavailable
from controller.operator.web import guard
from controller.operator.web.library import MAX_PROGRAM_BYTES, LibraryError
from controller.operator.web.openapi import openapi
from controller.operator.web.rpc import Api, RpcError, answer, call

MAX_REQUEST_BYTES = 1 << 20  # any request but an upload; any WebSocket message
MAX_QUEUED_MESSAGES = 1000  # events owed to one WebSocket beyond which it is dropped
AUTH_TIMEOUT_S = 10.0
MAX_CALLS_IN_FLIGHT = 16  # per WebSocket
STATUS_FRESH_S = 0.1  # GET /api/status polls the daemon when its status is older
STATIC = ("index.html", "panel.js", "panel.css", "preview.js")
HEADERS = {"X-Content-Type-Options": "nosniff", "X-Frame-Options": "DENY",
           "Referrer-Policy": "no-referrer", "Cache-Control": "no-store",
           "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; "
                                      "connect-src 'self'; frame-ancestors 'none'"}
API = web.AppKey("api", Api)
TOKEN = web.AppKey("token", object)
SESSIONS = web.AppKey("sessions", set)


class Session:
    """One WebSocket: its pushes go out in order, the status conflated to the newest (a slow
    tablet gets fewer statuses, never an ever-growing backlog)."""

    def __init__(self, ws: web.WebSocketResponse) -> None:
        self.ws = ws
        self.status: str | None = None
        self.events: deque[str] = deque()
        self.wake = asyncio.Event()
        self.dropped = False

    def push(self, kind: str, text: str) -> None:
        if kind == "status":
            self.status = text
        elif len(self.events) >= MAX_QUEUED_MESSAGES:
            self.dropped = True
        else:
            self.events.append(text)
        self.wake.set()

    async def sender(self) -> None:
        try:
            while not self.ws.closed and not self.dropped:
                await self.wake.wait()
                self.wake.clear()
                while self.events:
                    await self.ws.send_str(self.events.popleft())
                if self.status is not None:
                    text, self.status = self.status, None
                    await self.ws.send_str(text)
        except (ConnectionError, RuntimeError):
            pass  # the peer went away: the handler's loop ends and cleans up
        await self.ws.close()


def distribute(app: web.Application, kind: str, message: dict[str, Any]) -> None:
    """Serialised once, queued on every authenticated WebSocket."""
    text = json.dumps({"jsonrpc": "2.0", "method": kind, "params": message},
                      separators=(",", ":"))
    for session in app[SESSIONS]:
        session.push(kind, text)


@web.middleware
async def checks(request: web.Request, handler: Any) -> web.StreamResponse:
    """Origin, Host and token on every request but the panel's own files."""
    token = request.app[TOKEN]
    if not guard.origin_ok(request.headers.get("Origin"), request.host):
        return _refuse(403, "forbidden", "the Origin is not this server's")
    if token is None and not guard.loopback_host(request.host):
        return _refuse(403, "forbidden", "without a token only a loopback Host is served")
    api_path = request.path.startswith("/api/")
    if api_path and not guard.token_ok(token, guard.bearer(request.headers.get("Authorization"))):
        return _refuse(401, "unauthorised", "a valid token is needed (Authorization: Bearer)")
    response = await handler(request)
    response.headers.update(HEADERS)
    return response


def _refuse(status: int, reason: str, message: str) -> web.Response:
    return web.json_response({"error": {"reason": reason, "message": message}}, status=status,
                             headers=HEADERS)


async def static_file(request: web.Request) -> web.StreamResponse:
    name = request.match_info.get("name", "index.html")
    if name not in STATIC:
        raise web.HTTPNotFound()
    data = resources.files(__package__).joinpath("static", name).read_bytes()
    kind = {"html": "text/html", "js": "text/javascript", "css": "text/css"}[
        name.rsplit(".", 1)[1]]
    return web.Response(body=data, content_type=kind, charset="utf-8")


async def get_status(request: web.Request) -> web.Response:
    bridge = request.app[API].bridge
    if time.monotonic() - bridge.polled_s > STATUS_FRESH_S and not app_watched(request.app):
        try:  # nobody keeps the push going: ask the daemon now
            await bridge.poll()
        except (DaemonError, DaemonUnavailable):
            pass
    return web.json_response(bridge.status)


def app_watched(app: web.Application) -> bool:
    return bool(app[SESSIONS])


async def get_openapi(request: web.Request) -> web.Response:
    return web.json_response(openapi())


async def rpc_http(request: web.Request) -> web.Response:
    if (request.content_length or 0) > MAX_REQUEST_BYTES:
        return _refuse(413, "too-large", f"a request may have at most {MAX_REQUEST_BYTES} bytes")
    try:
        message = json.loads(await request.read())
    except ValueError:
        return _refuse(400, "malformed", "the body must be one JSON-RPC 2.0 request")
    # no owner: a continuous jog needs a WebSocket, whose closing stops it
    return web.json_response(await answer(request.app[API], message, None) or {})


async def program(request: web.Request) -> web.Response:
    """GET (text), POST (upload: the body, or a form's `file`), DELETE one program."""
    api, name = request.app[API], request.match_info["name"]
    try:
        if request.method == "GET":
            return web.Response(body=api.library.read(name), content_type="text/plain")
        if request.method == "DELETE":
            api.library.delete(name)
            return web.json_response({"deleted": name})
        if request.method not in ("POST", "PUT"):
            raise web.HTTPMethodNotAllowed(request.method, ["GET", "POST", "PUT", "DELETE"])
        return web.json_response(api.library.write(name, await _upload_body(request)))
    except LibraryError as exc:
        status = {"not-found": 404, "too-large": 413, "full": 507}.get(exc.code, 400)
        return _refuse(status, exc.code, exc.message)


async def _upload_body(request: web.Request) -> bytes:
    if (request.content_length or 0) > MAX_PROGRAM_BYTES + 4096:
        raise LibraryError("too-large", f"a program may have at most {MAX_PROGRAM_BYTES} bytes")
    if request.content_type == "multipart/form-data":
        form = await request.post()
        field = form.get("file")
        if field is None or not hasattr(field, "file"):
            raise LibraryError("bad-upload", "the form needs a file field")
        return field.file.read(MAX_PROGRAM_BYTES + 1)  # type: ignore[union-attr]
    return await request.read()


async def list_programs(request: web.Request) -> web.Response:
    return web.json_response({"programs": request.app[API].library.list()})


async def preview(request: web.Request) -> web.Response:
    try:
        result = await call(request.app[API], "programs.preview",
                            {"name": request.match_info["name"]}, None)
    except RpcError as exc:
        return _refuse(404 if exc.reason == "not-found" else 400, exc.reason or "bad",
                       exc.message)
    return web.json_response(result)


async def websocket(request: web.Request) -> web.WebSocketResponse:
    # a silent peer is dropped after about 15 s (a continuous jog does not wait: its lease)
    ws = web.WebSocketResponse(max_msg_size=MAX_REQUEST_BYTES, heartbeat=10.0)
    await ws.prepare(request)
    app, api = request.app, request.app[API]
    if not await _authenticate(ws, app[TOKEN]):
        await ws.close(code=4401, message=b"unauthorised")
        return ws
    session = Session(ws)
    app[SESSIONS].add(session)
    api.bridge.wake.set()
    sender = asyncio.create_task(session.sender())
    session.push("status", json.dumps({"jsonrpc": "2.0", "method": "status",
                                       "params": api.bridge.status}))
    calls: set[asyncio.Task[None]] = set()
    try:
        async for msg in ws:
            if msg.type != WSMsgType.TEXT:
                break
            try:
                message = json.loads(msg.data)
            except ValueError:
                message = None
            if len(calls) >= MAX_CALLS_IN_FLIGHT:
                session.push("reply", json.dumps({"jsonrpc": "2.0", "id": None, "error": {
                    "code": -32000, "message": "too many calls in flight"}}))
                continue
            # each call in a task of its own: a jog_stop never waits behind a long preview
            task = asyncio.create_task(_answer(api, message, session))
            calls.add(task)
            task.add_done_callback(calls.discard)
    finally:
        app[SESSIONS].discard(session)
        await api.jobs.jog_stop(session, why="connection closed")
        sender.cancel()
    return ws


async def _answer(api: Api, message: Any, session: Session) -> None:
    reply = await answer(api, message, session)
    if reply is not None:
        session.push("reply", json.dumps(reply))


async def _authenticate(ws: web.WebSocketResponse, token: str | None) -> bool:
    """With a token, the first message must be {"method": "auth", "params": {"token"}}."""
    if token is None:
        return True
    try:
        msg = await ws.receive(timeout=AUTH_TIMEOUT_S)
        message = json.loads(msg.data) if msg.type == WSMsgType.TEXT else None
    except (TimeoutError, ValueError):
        return False
    ok = isinstance(message, dict) and message.get("method") == "auth" and isinstance(
        message.get("params"), dict) and guard.token_ok(token, message["params"].get("token"))
    if ok:
        await ws.send_str(json.dumps({"jsonrpc": "2.0", "id": message.get("id"),
                                      "result": {"authenticated": True}}))
    return ok


def make_app(api: Api, token: str | None) -> web.Application:
    app = web.Application(middlewares=[checks], client_max_size=MAX_PROGRAM_BYTES + 4096)
    app[API], app[TOKEN], app[SESSIONS] = api, token, set()
    app.router.add_get("/", static_file)
    app.router.add_get("/static/{name}", static_file)
    app.router.add_get("/api/status", get_status)
    app.router.add_get("/api/openapi.json", get_openapi)
    app.router.add_post("/api/rpc", rpc_http)
    app.router.add_get("/api/programs", list_programs)
    app.router.add_route("*", "/api/programs/{name}", program)
    app.router.add_get("/api/programs/{name}/preview", preview)
    app.router.add_get("/ws", websocket)
    return app
