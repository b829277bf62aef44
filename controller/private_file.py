"""A secret kept in a file its owner alone may read (a token, a users file), read safely."""

from __future__ import annotations

import os
import stat


def read_private(path: str, max_bytes: int, error: type[Exception]) -> bytes:
    """The file's bytes; `error(message)` naming the path unless it is a regular file of this
    process's user that no one else may read or write, at most max_bytes long. Opened without
    following a link (a link could point anywhere) and without blocking (a FIFO put in its
    place would hang the service's start), as ssh treats a private key."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise error(f"{path}: cannot open: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as handle:
        info = os.fstat(handle.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise error(f"{path}: not a regular file")
        if info.st_uid != os.geteuid():
            raise error(
                f"{path}: owned by uid {info.st_uid}, not by this service's user "
                f"(uid {os.geteuid()})"
            )
        if info.st_mode & 0o077:
            raise error(
                f"{path}: mode {stat.S_IMODE(info.st_mode):o}: readable by others (chmod 600 it)"
            )
        raw = handle.read(max_bytes + 1)
    if len(raw) > max_bytes:
        raise error(f"{path}: larger than {max_bytes} bytes")
    return raw
