"""The program library: G-code files in one folder of the state directory, named by plain
names that cannot leave it, each written whole (a temporary file, fsync, rename) and capped."""

from __future__ import annotations

import os
import re
import stat
import time
from pathlib import Path
from typing import Any

MAX_PROGRAM_BYTES = 16 * 1024 * 1024  # one upload (the control socket takes up to 64 MiB)
MAX_LIBRARY_BYTES = 512 * 1024 * 1024  # all programs together
MAX_PROGRAMS = 1000
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
FOLDER = "programs"


class LibraryError(Exception):
    """A refused library operation: `code` for the API (bad-name, not-found, too-large, full)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code, self.message = code, message


def check_name(name: Any) -> str:
    """A program name: letters, digits, `.`, `_`, `-`, at most 100, not starting with a dot
    and without `..`: never a path, so it cannot leave the folder."""
    if not isinstance(name, str) or not NAME_RE.fullmatch(name) or ".." in name:
        raise LibraryError("bad-name", "a program name is 1-100 letters, digits, '.', '_' or "
                                       "'-', starting with a letter or digit, without '..'")
    return name


class Library:
    """One folder; every file is opened through the folder's descriptor without following
    links, and only regular files are listed or read."""

    def __init__(self, state_dir: Path) -> None:
        self.folder = state_dir / FOLDER
        self.folder.mkdir(mode=0o750, exist_ok=True)
        st = os.lstat(self.folder)
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
            raise LibraryError("bad-folder", f"{self.folder} is not a folder of this user")

    def _dir_fd(self) -> int:
        return os.open(self.folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)

    def list(self) -> list[dict[str, Any]]:
        out = []
        fd = self._dir_fd()
        try:
            for name in sorted(os.listdir(fd)):
                if not NAME_RE.fullmatch(name) or ".." in name:
                    continue  # temporary files and anything not ours
                try:
                    st = os.stat(name, dir_fd=fd, follow_symlinks=False)
                except OSError:
                    continue
                if stat.S_ISREG(st.st_mode):
                    out.append({"name": name, "bytes": st.st_size,
                                "modified": time.strftime("%Y-%m-%dT%H:%M:%S",
                                                          time.localtime(st.st_mtime))})
        finally:
            os.close(fd)
        return out

    def read(self, name: Any) -> bytes:
        name = check_name(name)
        fd = self._dir_fd()
        try:
            try:
                f = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=fd)
            except FileNotFoundError:
                raise LibraryError("not-found", "no such program") from None
            except OSError as exc:
                raise LibraryError("not-found", f"cannot open it: {exc.strerror}") from None
            with os.fdopen(f, "rb") as handle:
                st = os.fstat(handle.fileno())
                if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_PROGRAM_BYTES:
                    raise LibraryError("not-found", "not a program file")
                return handle.read(MAX_PROGRAM_BYTES + 1)[:MAX_PROGRAM_BYTES]
        finally:
            os.close(fd)

    def path(self, name: Any) -> str:
        """The file's path, for the interpreter (checked as read() checks it)."""
        self.read(name)
        return str(self.folder / check_name(name))

    def write(self, name: Any, data: bytes) -> dict[str, Any]:
        name = check_name(name)
        if len(data) > MAX_PROGRAM_BYTES:
            raise LibraryError("too-large", f"a program may have at most {MAX_PROGRAM_BYTES} "
                                            "bytes")
        entries = self.list()
        others = [e for e in entries if e["name"] != name]
        if len(others) >= MAX_PROGRAMS or sum(e["bytes"] for e in others) + len(data) \
                > MAX_LIBRARY_BYTES:
            raise LibraryError("full", f"the library holds at most {MAX_PROGRAMS} programs and "
                                       f"{MAX_LIBRARY_BYTES >> 20} MiB: delete some first")
        fd = self._dir_fd()
        tmp = f".upload-{os.getpid()}-{time.monotonic_ns()}"
        try:
            f = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o640,
                        dir_fd=fd)
            try:
                with os.fdopen(f, "wb") as handle:
                    handle.write(data)
                    handle.flush()
                    os.fsync(handle.fileno())
                os.rename(tmp, name, src_dir_fd=fd, dst_dir_fd=fd)
            except BaseException:
                os.unlink(tmp, dir_fd=fd)
                raise
        finally:
            os.close(fd)
        return {"name": name, "bytes": len(data)}

    def delete(self, name: Any) -> None:
        name = check_name(name)
        fd = self._dir_fd()
        try:
            os.unlink(name, dir_fd=fd)  # a link is removed as itself, never what it points to
        except FileNotFoundError:
            raise LibraryError("not-found", "no such program") from None
        except OSError as exc:
            raise LibraryError("not-found", f"cannot delete it: {exc.strerror}") from None
        finally:
            os.close(fd)
