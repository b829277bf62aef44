"""The control socket's per-process connect budget and the client's wait for a full queue."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from controller.operator.client import connect_unix
from controller.operator.daemon.connections import ConnectRate


def test_a_burst_then_the_rate() -> None:
    rate = ConnectRate(per_s=100, burst=10)
    assert all(rate.allow(7, 0.0) for _ in range(10))
    assert not rate.allow(7, 0.0)
    assert rate.allow(8, 0.0)  # another process has its own budget
    assert not rate.allow(7, 0.005)  # half a token back
    assert rate.allow(7, 0.011)


@given(st.lists(st.floats(0.0, 0.01), min_size=1, max_size=400))
def test_never_more_than_burst_plus_rate_times_time(gaps_s: list[float]) -> None:
    rate = ConnectRate(per_s=200, burst=20)
    now, allowed = 0.0, 0
    for gap in gaps_s:
        now += gap
        allowed += rate.allow(1, now)
    assert allowed <= 20 + 200 * now + 1e-9


def test_forgetting_keeps_the_table_small() -> None:
    rate = ConnectRate(per_s=100, burst=10)
    for pid in range(5000):
        rate.allow(pid, 0.0)
    rate.allow(1, 1.0)  # every bucket has refilled by now
    rate.allow(2, 1.0)
    assert len(rate._tokens) < 10


def _full_listener(path: Path) -> tuple[socket.socket, list[socket.socket]]:
    """A listener whose queue is full (nobody accepts), and the connections filling it."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen(0)
    fillers = []
    while True:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.setblocking(False)
        try:
            sock.connect(str(path))
        except BlockingIOError:
            sock.close()
            return listener, fillers
        fillers.append(sock)


def test_the_client_waits_for_room_in_a_full_queue(tmp_path: Path) -> None:
    listener, fillers = _full_listener(tmp_path / "s")
    try:
        def make_room() -> None:
            time.sleep(0.2)
            for _ in fillers:
                listener.accept()[0].close()
            listener.accept()[0].close()

        taker = threading.Thread(target=make_room)
        taker.start()
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(5.0)
            connect_unix(sock, str(tmp_path / "s"), 5.0)
        taker.join()
    finally:
        listener.close()
        for sock in fillers:
            sock.close()


def test_the_client_gives_up_at_its_time_out(tmp_path: Path) -> None:
    listener, fillers = _full_listener(tmp_path / "s")
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(0.3)
            t0 = time.monotonic()
            with pytest.raises(BlockingIOError):
                connect_unix(sock, str(tmp_path / "s"), 0.3)
            assert 0.25 < time.monotonic() - t0 < 3.0
    finally:
        listener.close()
        for sock in fillers:
            sock.close()
