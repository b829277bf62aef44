"""The reader of secrets (the web token, the OPC UA users file) refuses what it cannot trust."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from controller.operator.opcua.users import UsersFileError, read_users
from controller.operator.web.guard import TokenError, read_token
from controller.private_file import read_private


class Refused(Exception):
    pass


def _private(path, data: bytes = b"x" * 32, mode: int = 0o600):
    path.write_bytes(data)
    path.chmod(mode)
    return str(path)


def test_a_file_of_ours_that_no_one_else_reads_is_read(tmp_path) -> None:
    assert read_private(_private(tmp_path / "t"), 64, Refused) == b"x" * 32


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o620, 0o602])
def test_a_file_others_may_read_or_write_is_refused(tmp_path, mode: int) -> None:
    with pytest.raises(Refused, match=f"mode {mode:o}: readable by others"):
        read_private(_private(tmp_path / "t", mode=mode), 64, Refused)


def test_a_link_is_refused_even_to_a_good_file(tmp_path) -> None:
    good = _private(tmp_path / "t")
    (tmp_path / "link").symlink_to(good)
    with pytest.raises(Refused, match="cannot open"):
        read_private(str(tmp_path / "link"), 64, Refused)


def test_a_larger_file_is_refused(tmp_path) -> None:
    with pytest.raises(Refused, match="larger than 31 bytes"):
        read_private(_private(tmp_path / "t"), 31, Refused)


def test_a_fifo_in_the_files_place_is_refused_without_waiting_for_a_writer(tmp_path) -> None:
    # Run in a second process: a blocking open would hang it, and the timeout fails the test.
    fifo = tmp_path / "token"
    os.mkfifo(fifo, 0o600)
    code = textwrap.dedent(f"""
        from controller.operator.web.guard import TokenError, read_token
        try:
            read_token({str(fifo)!r})
        except TokenError as exc:
            print(exc)
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=30)
    assert done.stdout.strip() == f"{fifo}: not a regular file", done.stderr


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a file to another user needs root")
def test_a_file_of_another_user_is_refused_even_when_we_can_read_it(tmp_path) -> None:
    path = _private(tmp_path / "t")
    os.chown(path, 65534, 65534)
    with pytest.raises(Refused, match="owned by uid 65534"):
        read_private(path, 64, Refused)


def test_the_token_and_the_users_file_go_through_it(tmp_path) -> None:
    loose = _private(tmp_path / "loose", b"a" * 24 + b"\n", 0o644)
    with pytest.raises(TokenError, match="readable by others"):
        read_token(loose)
    with pytest.raises(UsersFileError, match="readable by others"):
        read_users(loose)
    assert read_token(_private(tmp_path / "tok", b"b" * 24 + b"\n")) == "b" * 24
