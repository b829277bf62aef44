"""Who may use the API: the token (on every HTTP request, and as the WebSocket's first
message), the Origin header (a page of another site cannot drive the machine) and, without a
token, the Host header (a DNS-rebound name cannot reach the loopback)."""

from __future__ import annotations

import hmac
import ipaddress
import os
import stat
from urllib.parse import urlsplit

MIN_TOKEN_CHARS = 16


class TokenError(ValueError):
    """A token file that cannot be used; the message says why."""


def read_token(path: str) -> str:
    """The token in a file readable by its owner only (as ssh wants of a key)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError as exc:
        raise TokenError(f"{path}: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as handle:
        st = os.fstat(handle.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise TokenError(f"{path}: not a regular file")
        if st.st_mode & 0o077:
            raise TokenError(f"{path}: readable by others (mode {st.st_mode & 0o777:o}): "
                             "chmod 600 it")
        token = handle.read(4096).decode("utf-8", "replace").strip()
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
