"""cncd's state directory, distrusted: its own user's, no symlink followed, only regular files read.

Everything goes through one descriptor of the directory (openat-style), so a name is never
resolved through a link planted in it: a `job-x` symlink to a folder once had that folder
emptied at start-up, a `journal.tmp` symlink had its target overwritten, `journal.json`
linked to /dev/zero never finished reading, and `offsets.json` as a FIFO blocked start-up.
"""

from __future__ import annotations

import errno
import itertools
import os
import shutil
import stat
import time
from pathlib import Path

from controller.errors import CncError

MAX_STATE_FILE_BYTES = 1 << 20  # the journal and the offset table are a few kB
_tmp_names = itertools.count()


class StateDirError(CncError):
    """The state directory or a file in it cannot be trusted: the daemon does not start."""


class StateFileError(CncError):
    """One state file is not what it should be (a link, a FIFO, too large)."""


class StateDir:
    """Open with the directory checked: owned by this process's user and writable by no one
    else, and so is every entry in it (a symlink's own owner counts; it is never followed)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if path.is_symlink():
            raise StateDirError(f"state directory {path}: a symbolic link (not followed): "
                                "refusing to start")
        path.mkdir(mode=0o750, parents=True, exist_ok=True)
        try:
            self.fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError as exc:
            raise StateDirError(f"state directory {path}: {_why(exc)}") from None
        try:
            self._check(os.fstat(self.fd), str(path), "state directory")
            for name in os.listdir(self.fd):
                entry = os.stat(name, dir_fd=self.fd, follow_symlinks=False)
                self._check(entry, str(path / name), "state file")
        except BaseException:
            os.close(self.fd)
            raise

    @staticmethod
    def _check(st: os.stat_result, where: str, what: str) -> None:
        me = os.geteuid()
        if st.st_uid != me:
            raise StateDirError(f"{what} {where} is owned by uid {st.st_uid}, not by this "
                                f"daemon's user (uid {me}): refusing to start")
        if not stat.S_ISLNK(st.st_mode) and st.st_mode & 0o022:
            raise StateDirError(f"{what} {where} is writable by others (mode "
                                f"{stat.S_IMODE(st.st_mode):04o}): refusing to start")

    def close(self) -> None:
        os.close(self.fd)

    def read(self, name: str, max_bytes: int = MAX_STATE_FILE_BYTES) -> bytes | None:
        """A regular file's bytes; None when there is none."""
        try:
            fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                         dir_fd=self.fd)
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise StateFileError(f"{self.path / name}: {_why(exc)}") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise StateFileError(f"{self.path / name}: not a regular file")
            data = os.read(fd, max_bytes + 1)
        finally:
            os.close(fd)
        if len(data) > max_bytes:
            raise StateFileError(f"{self.path / name}: larger than {max_bytes} bytes")
        return data

    def write_atomic(self, name: str, data: bytes, mode: int = 0o640) -> None:
        """A fresh temporary file (O_EXCL: never an existing name or link), fsync, rename
        over name, fsync of the directory: the old content or the new, never half."""
        tmp = f".{name}.{os.getpid()}.{next(_tmp_names)}.tmp"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                     mode, dir_fd=self.fd)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, name, src_dir_fd=self.fd, dst_dir_fd=self.fd)
        except BaseException:
            _unlink(self.fd, tmp)
            raise
        os.fsync(self.fd)

    def keep_aside(self, name: str) -> str:
        """Rename a bad file (or link) out of the way; the new name, which is reported."""
        aside = f"{name}.bad-{time.strftime('%Y%m%dT%H%M%S')}"
        for n in itertools.count(1):
            candidate = aside if n == 1 else f"{aside}-{n}"
            try:
                os.stat(candidate, dir_fd=self.fd, follow_symlinks=False)
            except FileNotFoundError:
                os.rename(name, candidate, src_dir_fd=self.fd, dst_dir_fd=self.fd)
                return candidate
        raise AssertionError("unreachable")

    def remove_leftovers(self, prefixes: tuple[str, ...]) -> list[str]:
        """Entries a crashed daemon left (job folders, program copies, temporary files):
        a link is removed itself, a folder with its content, none followed."""
        removed = []
        for name in os.listdir(self.fd):
            if not name.startswith(prefixes):
                continue
            st = os.stat(name, dir_fd=self.fd, follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode):
                shutil.rmtree(name, dir_fd=self.fd)  # fd-based: resists symlink attacks
            else:
                _unlink(self.fd, name)
            removed.append(name)
        return removed


def _unlink(dir_fd: int, name: str) -> None:
    try:
        os.unlink(name, dir_fd=dir_fd)
    except FileNotFoundError:
        pass


def _why(exc: OSError) -> str:
    if exc.errno == errno.ELOOP:
        return "a symbolic link (not followed)"
    return exc.strerror or str(exc)
