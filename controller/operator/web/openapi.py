"""The API document served at GET /api/openapi.json: the HTTP routes in OpenAPI 3.1, and the
JSON-RPC methods (the same table the server dispatches on) under `x-jsonrpc-methods`."""

from __future__ import annotations

from typing import Any

from controller.operator.web.rpc import METHODS

_JSON = {"application/json": {"schema": {"type": "object"}}}


def _op(summary: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
    op: dict[str, Any] = {"summary": summary,
                          "responses": {"200": {"description": "done", "content": _JSON},
                                        "401": {"description": "no valid token"},
                                        "403": {"description": "Origin or Host refused"}}}
    if body is not None:
        op["requestBody"] = {"content": body}
    return op


def openapi() -> dict[str, Any]:
    name = {"name": "name", "in": "path", "required": True,
            "schema": {"type": "string", "pattern": "^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$"}}
    text = {"text/plain": {"schema": {"type": "string"}},
            "multipart/form-data": {"schema": {"type": "object",
                                               "properties": {"file": {"type": "string",
                                                                       "format": "binary"}}}}}
    return {
        "openapi": "3.1.0",
        "info": {"title": "phcnc operator API", "version": "1",
                 "description": "Every request needs `Authorization: Bearer TOKEN` when a "
                                "token is configured; the WebSocket /ws takes it as its first "
                                "message. See docs/api.md."},
        "paths": {
            "/api/status": {"get": _op("the status pushed on the WebSocket (at least state)")},
            "/api/rpc": {"post": _op("one JSON-RPC 2.0 call (x-jsonrpc-methods)", _JSON)},
            "/api/programs": {"get": _op("the program library")},
            "/api/programs/{name}": {
                "parameters": [name],
                "get": _op("a program's text"),
                "post": _op("upload (the body, or a form's file field)", text),
                "put": _op("upload (the body)", text),
                "delete": _op("delete the program")},
            "/api/programs/{name}/preview": {"parameters": [name],
                                             "get": _op("the program's path, sampled")},
            "/ws": {"get": {"summary": "WebSocket: JSON-RPC 2.0 calls, and pushed "
                                       "notifications status (25 Hz), log, job, queue, jog",
                            "responses": {"101": {"description": "switching protocols"}}}},
        },
        "x-jsonrpc-methods": {m: {"params": sorted(params), "summary": doc}
                              for m, (_, params, doc) in sorted(METHODS.items())},
    }
