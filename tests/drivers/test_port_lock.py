"""One controller per port: the lock a backend holds while its drive is open."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.errors import DriveBusyError
from drivers.port_lock import PortLock, device_key


def test_a_second_holder_is_refused_with_the_first_ones_pid(tmp_path: Path) -> None:
    key = f"test-{tmp_path.name}"
    first, second = PortLock(key), PortLock(key)
    first.acquire()
    try:
        with pytest.raises(DriveBusyError, match=rf"in use by another controller process "
                                                 rf"\(pid {os.getpid()}\)"):
            second.acquire()
    finally:
        first.release()
    second.acquire()  # free again once released
    second.release()


def test_the_lock_goes_with_a_killed_process(tmp_path: Path) -> None:
    key = f"test-{tmp_path.name}"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from drivers.port_lock import PortLock; "
         f"PortLock({key!r}).acquire(); print('held', flush=True); time.sleep(60)"],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(DriveBusyError):
            PortLock(key).acquire()
    finally:
        holder.kill()
        holder.wait(timeout=10)
        if holder.stdout is not None:
            holder.stdout.close()
    lock = PortLock(key)
    lock.acquire()  # SIGKILL left no stale lock: the kernel dropped it with the process
    lock.release()


def test_a_symlinked_device_is_the_port_it_names(tmp_path: Path) -> None:
    real = tmp_path / "ttyACM0"
    real.write_text("")
    link = tmp_path / "by-id"
    link.symlink_to(real)
    assert device_key(str(link)) == device_key(str(real))
