"""Where the operator's web panel listens: `HOST:PORT` read and checked (the `service.http`
key and `cncd --http`), and whether that address is the loopback only."""

from __future__ import annotations

import ipaddress

DEFAULT_HOST = "127.0.0.1"


class ListenError(ValueError):
    """A listen address that cannot be used; the message says what is wrong with it."""


def parse_listen(text: str) -> tuple[str, int]:
    """`HOST:PORT`, `[V6]:PORT` or `:PORT` (the loopback) -> (host, port)."""
    if not isinstance(text, str) or not text or len(text) > 300:
        raise ListenError("must be HOST:PORT, e.g. 127.0.0.1:8080")
    host, sep, port_text = text.rpartition(":")
    if not sep or not port_text.isdigit():
        raise ListenError("must be HOST:PORT with a port number, e.g. 127.0.0.1:8080")
    port = int(port_text)
    if not 1 <= port <= 65535:
        raise ListenError(f"port must be 1..65535, got {port}")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    host = host or DEFAULT_HOST
    if not all(c.isalnum() or c in ".-:" for c in host):
        raise ListenError("the host must be a name or an address")
    return host, port


def is_loopback(host: str) -> bool:
    """True only for a loopback address or `localhost`: anything else may be reached from the
    network, and needs a token."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
