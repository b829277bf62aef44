"""Who may call the OPC UA methods: a users file of `name:pbkdf2_sha256$rounds$salt$hash`
lines, readable by cncd's user only (refused otherwise, like the state directory), and the
command that writes a line (`python -m controller.operator.opcua.users NAME`)."""

from __future__ import annotations

import getpass
import hashlib
import hmac
import secrets
import sys

from controller.errors import CncError
from controller.private_file import read_private

ROUNDS = 200_000
MAX_FILE_BYTES = 64 * 1024
SCHEME = "pbkdf2_sha256"


class UsersFileError(CncError):
    """The users file cannot be trusted or read; the message names it and why."""


def hash_password(password: str, rounds: int = ROUNDS, salt: str | None = None) -> str:
    salt = salt or secrets.token_hex(16)
    digest = hashlib.pbkdf2_hmac("sha256", password.encode(), bytes.fromhex(salt), rounds)
    return f"{SCHEME}${rounds}${salt}${digest.hex()}"


def check_password(password: str, stored: str) -> bool:
    try:
        scheme, rounds, salt, digest = stored.split("$")
        if scheme != SCHEME or not 1000 <= int(rounds) <= 10_000_000:
            return False
        mine = hash_password(password, int(rounds), salt).rsplit("$", 1)[1]
    except ValueError:
        return False
    return hmac.compare_digest(mine, digest)


def read_users(path: str) -> dict[str, str]:
    """name -> stored hash. Refused: not a regular file of ours, readable or writable by
    anyone else, a link, too large, or a line that is not `name:hash`."""
    raw = read_private(path, MAX_FILE_BYTES, UsersFileError)
    users: dict[str, str] = {}
    for number, line in enumerate(raw.decode("utf-8", "replace").splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        name, sep, stored = line.partition(":")
        if not sep or not name or not stored.startswith(SCHEME + "$"):
            raise UsersFileError(f"{path}:{number}: not `name:{SCHEME}$...` (write lines with "
                                 "python -m controller.operator.opcua.users NAME)")
        users[name] = stored
    return users


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1 or ":" in args[0]:
        print("usage: python -m controller.operator.opcua.users NAME  (the password is read "
              "from the terminal, or from stdin)", file=sys.stderr)
        return 2
    password = getpass.getpass() if sys.stdin.isatty() else sys.stdin.readline().rstrip("\n")
    if len(password) < 8:
        print("a password of at least 8 characters", file=sys.stderr)
        return 2
    print(f"{args[0]}:{hash_password(password)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
