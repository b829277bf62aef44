"""The slcan reader (whole lines, bad lines counted) and the SYNC/TPDO1 pairing of the link."""

from __future__ import annotations

import os
import time
import tty
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from controller.config import load_config
from drivers.base import CardStatus
from drivers.canopen import cia402 as c
from drivers.canopen.link import Link
from drivers.canopen.options import parse_options
from drivers.canopen.slcan_lines import LineSlcanBus
from drivers.canopen.slcan_pty import SlcanPty, encode

CONFIG = load_config("canopen")


@pytest.fixture
def pty_bus() -> Any:
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    bus = LineSlcanBus(os.ttyname(slave_fd), sleep_after_open=0)
    os.read(master_fd, 4096)  # the C / O the bus sent on open
    try:
        yield master_fd, bus
    finally:
        bus.shutdown()
        os.close(master_fd)
        os.close(slave_fd)


def _receive(bus: LineSlcanBus, n: int, timeout_s: float = 2.0) -> list[Any]:
    got: list[Any] = []
    deadline_s = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline_s:
        msg = bus.recv(0.05)
        if msg is not None:
            got.append(msg)
    return got


def test_many_lines_in_one_chunk_and_a_line_cut_across_two_reads(pty_bus: Any) -> None:
    master_fd, bus = pty_bus
    lines = [f"t18{i % 2 + 1}6{c.PDO1.pack(i, i * 7).hex().upper()}\r" for i in range(200)]
    text = "z\r".join(lines).encode()
    os.write(master_fd, text[:1001])
    time.sleep(0.05)
    os.write(master_fd, text[1001:])
    msgs = _receive(bus, 200)
    assert [m.arbitration_id for m in msgs] == [0x181 + i % 2 for i in range(200)]
    assert [c.PDO1.unpack(bytes(m.data)) for m in msgs] == [(i, i * 7) for i in range(200)]
    assert bus.bad_lines == 0


@pytest.mark.parametrize("garbage", [b"t1\r", b"t18G6000000000000\r", b"t1816000000\r",
                                     b"x" * 100 + b"\r"])
def test_a_garbled_line_is_counted_and_the_next_frame_still_arrives(pty_bus: Any,
                                                                     garbage: bytes) -> None:
    """python-can's own reader raised ValueError in the receive thread on such a line."""
    master_fd, bus = pty_bus
    os.write(master_fd, garbage + b"t1816010002000000\r")
    msgs = _receive(bus, 1)
    assert len(msgs) == 1 and c.PDO1.unpack(bytes(msgs[0].data)) == (1, 2)
    assert bus.bad_lines == 1 and bus.last_bad_line


def test_the_simulated_adapter_never_cuts_a_line_for_a_slow_host() -> None:
    """The host does not read for 0.3 s while 300 frames are sent: it then reads them all,
    whole (a pty holds about 4 KB: the adapter waits, it does not cut or drop)."""
    import can

    adapter = SlcanPty("t-slow-host")
    adapter.start()
    sender = can.Bus(interface="virtual", channel="t-slow-host")
    try:
        fd = os.open(adapter.path, os.O_RDWR | os.O_NOCTTY)
        os.write(fd, b"O\r")
        time.sleep(0.05)
        msgs = [can.Message(arbitration_id=0x181, is_extended_id=False,
                            data=c.PDO1.pack(0x1237, i)) for i in range(300)]
        for msg in msgs:
            sender.send(msg)
        time.sleep(0.3)
        data = b""
        deadline_s = time.monotonic() + 3.0
        want = b"\r" + b"".join(encode(m) for m in msgs)  # the ack of O, then the frames
        while len(data) < len(want) and time.monotonic() < deadline_s:
            os.set_blocking(fd, False)
            try:
                data += os.read(fd, 65536)
            except BlockingIOError:
                time.sleep(0.01)
        os.close(fd)
        assert data == want
        assert adapter.dropped == 0
    finally:
        sender.shutdown()
        adapter.close()


# -- pairing ------------------------------------------------------------------------------
class _Node:
    def __init__(self, node_id: int) -> None:
        self.id = node_id
        self.rpdo = {1: SimpleNamespace(data=bytearray(6))}
        self.emcy = SimpleNamespace(add_callback=lambda cb: None)
        self.nmt = SimpleNamespace(add_heartbeat_callback=lambda cb: None)


def _link() -> Link:
    network = SimpleNamespace(subscribers={}, notifier=None, bus=None,
                              send_message=lambda cob, data: None)
    o = parse_options(CONFIG, dict(CONFIG.drive.options))
    link = Link(network, [_Node(1), _Node(2)], CONFIG.axis_names, o, CONFIG.sample_period_s,
                np.array([a.pulse_mm for a in CONFIG.axes]))
    link.rebase([0, 0])
    link.supervising = True
    return link


def _answer(link: Link, k: int) -> None:
    """Both drives' TPDO1 for SYNC k: their position is the target sent at k, so a pairing
    with the wrong SYNC shows as a difference between commanded and encoder counts."""
    now_s = time.monotonic()
    with link.lock:
        link.last_hb_s = [now_s] * link.n
        for i in range(link.n):
            link._on_tpdo(i, c.STATE_BITS["OPERATION ENABLED"], int(link.sent[k][i]), now_s)


def _stream(link: Link, cycles: int, max_delay: int) -> None:
    """The host's reader falls behind by one TPDO1 every other cycle up to max_delay (a
    TPDO1 still arrives almost every cycle, so none is overdue), then keeps pace."""
    link.sent = {}
    link.fifo.push(np.tile([50, -50], (cycles, 1)).astype(np.int64), 0, False)
    link.streaming = True
    answered = 0
    for k in range(1, cycles + 1):
        link.cycle()
        link.sent[k] = link._targets()
        delay = min(max_delay, k // 2)
        while answered < k - delay:
            answered += 1
            _answer(link, answered)


def test_late_feedback_is_paired_with_its_own_sync() -> None:
    link = _link()
    _stream(link, 250, max_delay=60)
    seq, cmd, enc = link.take_trace()
    assert len(seq) == 190 and link.status == CardStatus.OK
    assert np.array_equal(cmd, enc)


def test_feedback_further_behind_than_the_limit_is_lost_communication() -> None:
    """Dropping the oldest SYNC instead paired every later TPDO1 with the wrong target: a
    host reading 110 ms late saw 5.5 mm of invented following error."""
    link = _link()
    _stream(link, 250, max_delay=link.max_pending + 8)
    assert CardStatus.LOST_COMM in link.status
    assert "SYNC cycles behind" in "; ".join(link.messages)
    trace = link.take_trace()
    if trace is not None:
        _, cmd, enc = trace
        assert np.array_equal(cmd, enc)


def test_a_garbled_adapter_line_latches_a_fault() -> None:
    link = _link()
    link.network.bus = SimpleNamespace(bad_lines=0, last_bad_line="")
    link.bad_lines = 0
    link.cycle()
    assert link.status == CardStatus.OK
    link.network.bus.bad_lines, link.network.bus.last_bad_line = 1, "t18"
    link.cycle()
    assert CardStatus.FAULT in link.status
    assert "corrupt frame from the CAN adapter" in "; ".join(link.messages)


def test_a_drive_heartbeat_is_not_judged_late_while_the_reader_is_behind() -> None:
    """Its heartbeat may be among the frames not yet read: judging then invented a lost
    drive on a loaded host; once the reader has caught up, a silent drive is lost."""
    link = _link()
    behind = [True]
    link.network.bus = SimpleNamespace(bad_lines=0, behind=lambda: behind[0])
    link.last_hb_s = [time.monotonic() - 1.0] * link.n
    link.last_tpdo_cycle = [link.cycle_no + 1] * link.n
    link.cycle()
    assert link.status == CardStatus.OK
    behind[0] = False
    link.cycle()
    assert CardStatus.LOST_COMM in link.status and "no heartbeat" in "; ".join(link.messages)


def test_one_empty_read_of_the_pty_is_not_a_lost_device(pty_bus: Any) -> None:
    """The adapter flushing its queue as it opens leaves select ready and nothing to read:
    pyserial calls that a disconnect, and a reset after a replug failed reading 0x1000."""
    import serial

    master_fd, bus = pty_bus
    real = bus.serialPortOrig.read
    calls = [0]

    def flaky(n: int = 1) -> bytes:
        calls[0] += 1
        if calls[0] == 1:
            raise serial.SerialException("device reports readiness to read but returned no "
                                         "data (device disconnected or multiple access on port?)")
        return real(n)

    bus.serialPortOrig.read = flaky
    os.write(master_fd, b"t1816010002000000\r")
    msgs = _receive(bus, 1)
    assert len(msgs) == 1 and calls[0] > 1
