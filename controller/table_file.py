"""Small table files (work offsets, tools) kept by an operator or cncd: read within a size cap,
written atomically so that a crash leaves the old table or the new one, never half of one."""

from __future__ import annotations

import os
from collections.abc import Callable

Error = Callable[[str, str], Exception]  # (file name, message) -> the caller's error


def read_capped(name: str, max_bytes: int, what: tuple[str, str], error: Error,
                missing_ok: bool) -> bytes | None:
    """The file's bytes; None when it does not exist and missing_ok. what: ("offset table",
    "an offset table"), for the messages."""
    try:
        with open(name, "rb") as f:
            raw = f.read(max_bytes + 1)
    except FileNotFoundError as exc:
        if not missing_ok:
            raise error(name, f"no such {what[0]}") from exc
        return None
    except OSError as exc:
        raise error(name, f"cannot read the {what[0]}: {exc.strerror or exc}") from exc
    if len(raw) > max_bytes:
        raise error(name, f"not {what[1]}: larger than {max_bytes} bytes")
    return raw


def write_atomic(name: str, text: str, prefix: str, what: str, error: Error,
                 mode: int | None = None) -> None:
    """Write text to name: a temporary file in the same folder (with mode, if given), fsync,
    os.replace, then fsync of the folder."""
    import tempfile  # here: reading tables (every command's start-up) does not need it

    folder = os.path.dirname(os.path.abspath(name))
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=".tmp", dir=folder)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            if mode is not None:
                os.fchmod(f.fileno(), mode)
            os.fsync(f.fileno())
        os.replace(tmp, name)
        tmp = None
        fsync_folder(folder)
    except OSError as exc:
        raise error(name, f"cannot write the {what}: {exc.strerror or exc}") from exc
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def fsync_folder(folder: str) -> None:
    """Make the rename durable (not every file system lets a folder be opened: best effort)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
