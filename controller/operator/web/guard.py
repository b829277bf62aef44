"""Who may use the API: the token (on every HTTP request, and as the WebSocket's first
message), the Origin header (a page of another site cannot drive the machine) and, without a
token, the Host header (a DNS-rebound name cannot reach the loopback)."""

from __future__ import annotations

import hmac
import ipaddress
from urllib.parse import urlsplit

from controller.private_file import read_private

MIN_TOKEN_CHARS = 16
MAX_TOKEN_FILE_BYTES = 4096


class TokenError(ValueError):
    """A token file that cannot be used; the message says why."""


def read_token(path: str) -> str:
    """The token in a file of this user's that no one else may read (as ssh wants of a key)."""
    token = read_private(path, MAX_TOKEN_FILE_BYTES, TokenError).decode("utf-8", "replace").strip()
    if len(token) < MIN_TOKEN_CHARS or not token.isprintable() or " " in token:
        raise TokenError(f"{path}: the token must be at least {MIN_TOKEN_CHARS} printable "
                         "characters without spaces (e.g. `openssl rand -hex 24`)")
    return token


def token_ok(expected: str | None, given: object) -> bool:
    if expected is None:
        return True
    return isinstance(given, str) and hmac.compare_digest(given.encode(), expected.encode())


def bearer(header: str | None) -> str | None:
    if header and header.startswith("Bearer "):
        return header[len("Bearer "):].strip()
    return None


def origin_ok(origin: str | None, host: str | None) -> bool:
    """No Origin (a program, not a page) or the page's own origin (same host and port)."""
    if origin is None:
        return True
    parts = urlsplit(origin)
    return parts.scheme in ("http", "https") and host is not None \
        and parts.netloc.lower() == host.lower()


def loopback_host(host: str | None) -> bool:
    """The Host header names the loopback (localhost, 127.x.y.z, [::1]), with any port."""
    if not host:
        return False
    name = urlsplit(f"//{host}").hostname or ""
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False
