"""One controller per drive: an exclusive lock on the port or bus a backend opens, while open."""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import tempfile

from drivers.errors import DriveBusyError

LOCK_DIRS = ("/run/lock", "/var/lock")  # shared by every user, as for serial ports (FHS)


def lock_path(key: str) -> str:
    """The lock file of a port or bus: in /run/lock when writable (so every user and cncd see
    it), else in the temporary folder."""
    folder = next((d for d in LOCK_DIRS if os.access(d, os.W_OK | os.X_OK)),
                  tempfile.gettempdir())
    return os.path.join(folder, "phcnc-" + re.sub(r"[^A-Za-z0-9_.-]", "_", key) + ".lock")


class PortLock:
    """flock on a lock file named after what the backend opens (a device's real path, or a
    CAN interface and channel). A second `cncctl run`, `check` or `cncd` on the same port used
    to open it too, reset the card and wreck the job moving on it; now it is refused and the
    first one is untouched. The kernel drops the lock with the process, however it ends."""

    def __init__(self, key: str) -> None:
        self.key = key
        self.path = lock_path(key)
        self._fd: int | None = None

    def acquire(self) -> None:
        if self._fd is not None:
            return
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_pid(fd)
            os.close(fd)
            raise DriveBusyError(f"{self.key} is in use by another controller process"
                                 + (f" (pid {holder})" if holder else "")
                                 + ": one cncd or cncctl run per drive") from None
        except OSError:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        with contextlib.suppress(OSError):  # another user's umask: let them lock it too
            os.fchmod(fd, 0o666)
        self._fd = fd

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)  # the file stays: removing it would race with the next locker


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode().strip()
        return int(text) if text.isdigit() else None
    except (OSError, UnicodeDecodeError):
        return None


def device_key(path: str) -> str:
    """A device path as its lock key: the real path (a symlink such as /dev/serial/by-id/... and
    the tty it names are one port)."""
    return os.path.realpath(path)
