"""The control socket's wire format: JSON lines, size limits, request checks (docs/)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

MAX_LINE_BYTES = 64 * 1024  # any request line
MAX_PROGRAM_BYTES = 64 * 1024 * 1024  # the program text that follows a run request
COMMANDS = frozenset({"status", "run", "abort", "estop", "reset", "log", "subscribe",
                      "resume", "hold", "feed", "home", "jog", "offset", "identify",
                      "tool"})
MAX_FEED_OVERRIDE_PCT = 150.0
TOPICS = frozenset({"state", "progress", "log"})


class ProtocolError(Exception):
    """A request the daemon refuses; `code` is the machine-readable reason. The message never
    repeats what the client sent (a reply must not echo a 100 MB line or a secret)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class Request:
    id: Any  # echoed in the reply (int, str or None)
    cmd: str
    fields: dict[str, Any]


def encode(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, separators=(",", ":")) + "\n").encode()


def reply_ok(request_id: Any, **fields: Any) -> bytes:
    return encode({"id": request_id, "ok": True, **fields})


def reply_error(request_id: Any, code: str, message: str) -> bytes:
    return encode({"id": request_id, "ok": False, "error": code, "message": message})


def _id_of(obj: dict[str, Any]) -> Any:
    rid = obj.get("id")
    if rid is None:
        return None
    if isinstance(rid, bool) or not isinstance(rid, int | str) or \
            isinstance(rid, str) and len(rid) > 64 or isinstance(rid, int) and abs(rid) >= 2**63:
        raise ProtocolError("bad-field", "id must be an integer or a text of at most 64 "
                                         "characters")
    return rid


def parse_request(line: bytes) -> Request:
    """One request line (without its newline) -> Request, or ProtocolError."""
    try:
        obj = json.loads(line.decode("utf-8"), object_pairs_hook=_unique_keys)
    except _DuplicateKey:
        # {"cmd": "status", "cmd": "estop"} was an e-stop (the last key won): a request
        # that says two things is refused.
        raise ProtocolError("malformed", "a request names a field twice") from None
    except (ValueError, RecursionError):
        # ValueError: undecodable bytes, bad JSON, and an integer of more than 4300 digits
        # (which once took the daemon down mid-job).
        raise ProtocolError("malformed", "a request is one JSON object per line") from None
    if not isinstance(obj, dict):
        raise ProtocolError("malformed", "a request is one JSON object per line")
    cmd = obj.get("cmd")
    if not isinstance(cmd, str) or cmd not in COMMANDS:
        raise ProtocolError("unknown-command",
                            f"unknown command; known: {', '.join(sorted(COMMANDS))}")
    fields = {k: v for k, v in obj.items() if k not in ("id", "cmd")}
    request = Request(_id_of(obj), cmd, fields)
    _CHECKS.get(cmd, _no_fields)(request)
    return request


class _DuplicateKey(Exception):
    pass


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        raise _DuplicateKey
    return out


def _follow(request: Request) -> None:
    if not isinstance(request.fields.get("follow", False), bool):
        raise ProtocolError("bad-field", "follow must be true or false")


def _no_fields(request: Request) -> None:
    extra = set(request.fields)
    if extra:
        raise ProtocolError("bad-field", f"{request.cmd} takes no field "
                                         f"{sorted(extra)[0][:32]!r}")


def _check_run(request: Request) -> None:
    f = request.fields
    _known(request, {"name", "program_bytes", "follow", "optional_stop", "from_line"})
    line = f.get("from_line")
    if line is not None and (not isinstance(line, int) or isinstance(line, bool) or line < 1):
        raise ProtocolError("bad-field", "from_line must be a line number (1 or more)")
    if not isinstance(f.get("optional_stop", False), bool):
        raise ProtocolError("bad-field", "optional_stop must be true or false")
    _follow(request)
    size = f.get("program_bytes")
    if not isinstance(size, int) or isinstance(size, bool) or size < 0:
        raise ProtocolError("bad-field", "run needs program_bytes, the size of the program "
                                         "text that follows the line")
    if size > MAX_PROGRAM_BYTES:
        raise ProtocolError("too-large", f"program larger than {MAX_PROGRAM_BYTES} bytes")
    name = f.get("name", "program.nc")
    if not isinstance(name, str) or not 0 < len(name) <= 255 or "\n" in name:
        raise ProtocolError("bad-field", "name must be a short one-line text")


def _check_log(request: Request) -> None:
    _known(request, {"lines", "follow"})
    _follow(request)
    lines = request.fields.get("lines", 50)
    if not isinstance(lines, int) or isinstance(lines, bool) or not 0 <= lines <= 100_000:
        raise ProtocolError("bad-field", "lines must be an integer 0..100000")


def _check_subscribe(request: Request) -> None:
    _known(request, {"topics"})
    topics = request.fields.get("topics", ["state"])
    if not isinstance(topics, list) or not topics or not all(
            isinstance(t, str) and t in TOPICS for t in topics):
        raise ProtocolError("bad-field", f"topics: a list of {', '.join(sorted(TOPICS))}")


def _known(request: Request, allowed: set[str]) -> None:
    extra = set(request.fields) - allowed
    if extra:
        raise ProtocolError("bad-field", f"{request.cmd} takes no field "
                                         f"{sorted(extra)[0][:32]!r}")


def _check_feed(request: Request) -> None:
    _known(request, {"percent"})
    pct = request.fields.get("percent")
    if not isinstance(pct, int | float) or isinstance(pct, bool) \
            or not 0.0 <= pct <= MAX_FEED_OVERRIDE_PCT:
        raise ProtocolError("bad-field",
                            f"feed needs percent, a number 0..{MAX_FEED_OVERRIDE_PCT:g}")


def _check_home(request: Request) -> None:
    _known(request, {"axes"})
    _axes(request)


def _axes(request: Request) -> None:
    axes = request.fields.get("axes", [])
    if not isinstance(axes, list) or not all(isinstance(a, str) and len(a) == 1 for a in axes):
        raise ProtocolError("bad-field", "axes must be a list of axis letters")


def _number(request: Request, key: str, lo: float, hi: float, required: bool = False) -> None:
    value = request.fields.get(key)
    if value is None and not required:
        return
    if not isinstance(value, int | float) or isinstance(value, bool) or not lo <= value <= hi:
        raise ProtocolError("bad-field", f"{key} must be a number {lo:g}..{hi:g}")


def _check_jog(request: Request) -> None:
    _known(request, {"axis", "distance_mm", "direction", "feed_mm_min", "timeout_s", "follow"})
    _follow(request)
    axis = request.fields.get("axis")
    if not isinstance(axis, str) or len(axis) != 1:
        raise ProtocolError("bad-field", "jog needs axis, one letter")
    _number(request, "distance_mm", -1e4, 1e4)
    _number(request, "direction", -1, 1)
    _number(request, "feed_mm_min", 1e-3, 1e6)
    _number(request, "timeout_s", 0.1, 3600.0)
    if ("distance_mm" in request.fields) == ("direction" in request.fields):
        raise ProtocolError("bad-field", "jog needs distance_mm (incremental) or direction "
                                         "(continuous), not both")


def _check_offset(request: Request) -> None:
    _known(request, {"action", "system", "values", "here"})
    f = request.fields
    if f.get("action") not in ("set", "select", "clear-g92"):
        raise ProtocolError("bad-field", "action must be set, select or clear-g92")
    values = f.get("values", {})
    if not isinstance(values, dict) or not all(
            k in ("x", "y", "z") and isinstance(v, int | float) and not isinstance(v, bool)
            and abs(v) < 1e5 for k, v in values.items()):
        raise ProtocolError("bad-field", "values must map x, y, z to numbers")
    if not isinstance(f.get("here", False), bool) or not isinstance(f.get("system", ""), str):
        raise ProtocolError("bad-field", "here must be true or false, system a name")


def _check_identify(request: Request) -> None:
    _known(request, {"axes", "window_mm", "duration_s", "follow", "plan_only", "from_mm"})
    _follow(request)
    _axes(request)
    _number(request, "window_mm", 1e-3, 1e4)
    _number(request, "duration_s", 1.0, 30.0)
    f = request.fields
    if not isinstance(f.get("plan_only", False), bool):
        raise ProtocolError("bad-field", "plan_only must be true or false")
    shown = f.get("from_mm", {})
    if not isinstance(shown, dict) or not all(
            isinstance(k, str) and len(k) == 1 and isinstance(v, int | float)
            and not isinstance(v, bool) and abs(v) < 1e5 for k, v in shown.items()):
        raise ProtocolError("bad-field", "from_mm must map axis letters to numbers")


def _check_tool(request: Request) -> None:
    """`tool`: list, set (tool, pocket, length_mm, diameter_mm, comment) or delete (tool)."""
    _known(request, {"action", "tool", "pocket", "length_mm", "diameter_mm", "comment"})
    f = request.fields
    if f.get("action") not in ("list", "set", "delete"):
        raise ProtocolError("bad-field", "action must be list, set or delete")
    if f["action"] != "list" and "tool" not in f:
        raise ProtocolError("bad-field", f"{f['action']} needs tool")
    for key in ("tool", "pocket"):
        if isinstance(f.get(key, 1), bool) or not isinstance(f.get(key, 1), int):
            raise ProtocolError("bad-field", f"{key} must be an integer")
    for key in ("length_mm", "diameter_mm"):
        value = f.get(key, 0.0)
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value):
            raise ProtocolError("bad-field", f"{key} must be a number")
    if not isinstance(f.get("comment", ""), str) or len(f.get("comment", "")) > 200:
        raise ProtocolError("bad-field", "comment must be a text of at most 200 characters")


_CHECKS = {"tool": _check_tool, "offset": _check_offset, "run": _check_run, "log": _check_log,
           "subscribe": _check_subscribe, "feed": _check_feed, "home": _check_home,
           "jog": _check_jog, "identify": _check_identify}


class LineReader:
    """Bytes in; request lines or raw program bytes out, one at a time (the program text after a
    run line holds newlines of its own). A request line longer than MAX_LINE_BYTES is an error
    at once: the daemon never buffers more than that waiting for a newline."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        self._buf += data

    def next_line(self) -> bytes | None:
        end = self._buf.find(b"\n", 0, MAX_LINE_BYTES + 1)
        if end < 0:
            if len(self._buf) > MAX_LINE_BYTES:
                raise ProtocolError("too-large",
                                    f"request line longer than {MAX_LINE_BYTES} bytes")
            return None
        line = bytes(self._buf[:end])
        del self._buf[: end + 1]
        return line

    def take(self, n: int) -> bytes:
        """Up to n bytes already buffered (the program text after a run line)."""
        out = bytes(self._buf[:n])
        del self._buf[:n]
        return out

    @property
    def pending(self) -> int:
        return len(self._buf)
