"""Who may use the control socket: the socket file's group and mode, and SO_PEERCRED checks."""

from __future__ import annotations

import errno
import grp
import os
import pwd
import socket
import stat
from pathlib import Path

from controller.config import ServiceConfig
from controller.operator.daemon.protocol import ProtocolError


class AccessPolicy:
    """Root, the daemon's own user, and members of the allowed groups (socket group first)."""

    def __init__(self, service: ServiceConfig, socket_gid: int) -> None:
        self.uids = {0, os.geteuid()} | {_uid(u) for u in service.allowed_users}
        self.gids = {socket_gid} | {_gid(g) for g in service.allowed_groups}

    def allows(self, pid: int, uid: int, gid: int) -> bool:
        return uid in self.uids or gid in self.gids or bool(self.gids & _groups_of(pid))


def _uid(name: str) -> int:
    try:
        return pwd.getpwnam(name).pw_uid
    except KeyError:
        raise ProtocolError("config", f"service.allowed_users: no user {name!r}") from None


def _gid(name: str) -> int:
    try:
        return grp.getgrnam(name).gr_gid
    except KeyError:
        raise ProtocolError("config", f"service group {name!r} does not exist") from None


def _groups_of(pid: int) -> set[int]:
    """The peer process's supplementary groups (what it runs with, not what /etc/group says)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("Groups:"):
                return {int(g) for g in line.split()[1:]}
    except (OSError, ValueError):
        pass
    return set()


def socket_gid(service: ServiceConfig) -> int:
    return _gid(service.socket_group) if service.socket_group else os.getegid()


def bind_socket(path: str, gid: int) -> socket.socket:
    """Listening socket at path, mode 0660 and group gid whatever the umask; a stale socket
    file is replaced, a live one (another daemon) is an error."""
    if os.path.exists(path):
        if not stat.S_ISSOCK(os.lstat(path).st_mode):
            raise OSError(errno.EEXIST, f"{path} exists and is not a socket")
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            probe.connect(path)
            raise OSError(errno.EADDRINUSE, f"another daemon answers on {path}")
        except (ConnectionRefusedError, FileNotFoundError):
            os.unlink(path)
        finally:
            probe.close()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
    old = os.umask(0o177)  # the file is born 0600: nobody else can connect before the chmod
    try:
        sock.bind(path)
    finally:
        os.umask(old)
    if gid != os.getegid() or os.geteuid() == 0:
        os.chown(path, -1, gid)
    os.chmod(path, 0o660)
    # The kernel's most (net.core.somaxconn): under a flood of reconnections a short queue
    # stayed full and an operator's connect failed at once with EAGAIN.
    sock.listen(socket.SOMAXCONN)
    sock.setblocking(False)
    return sock
