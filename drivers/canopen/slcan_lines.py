"""python-can's slcan bus reading whole Lawicel lines per system call, and refusing bad ones."""

from __future__ import annotations

import collections
import threading
import time
from typing import Any

import can
import serial
from can.interfaces.slcan import slcanBus

TERMINATORS = (ord("\r"), ord("\a"))
MAX_EMPTY_READS = 100  # in a row, 1 ms apart: the device is gone
MAX_LINE_BYTES = 64  # the longest Lawicel line is 27 bytes (T, 8 id, 1 dlc, 16 data, CR)


class LineSlcanBus(slcanBus):
    """slcanBus whose reader takes every byte the adapter has sent in one read and splits it
    into lines.

    python-can 4.x reads one byte per system call: at 1 ms, with two drives, that is about 60
    calls a millisecond on the receive thread. Under load it fell behind, the pty filled, and
    late TPDOs were paired with the wrong SYNC. A line it cannot parse raised ValueError in the
    receive thread, which then stopped ("invalid literal for int() with base 16: '\\r'");
    here it is counted and skipped, and `bad_lines` tells the link a frame was lost."""

    def __init__(self, channel: str, **kwargs: Any) -> None:
        self._lines: collections.deque[str] = collections.deque()
        self._line_lock = threading.Lock()
        self.bad_lines = 0
        self.last_bad_line = ""
        self._empty_reads = 0
        super().__init__(channel, **kwargs)

    def _read(self, timeout: float | None) -> str | None:
        port = self.serialPortOrig
        deadline_s = time.monotonic() + (timeout or 0.0)
        while True:
            with self._line_lock:
                if self._lines:
                    return self._lines.popleft()
            try:
                waiting = port.in_waiting
                chunk = port.read(waiting if waiting else 1)  # 1: waits up to the time-out
            except serial.SerialException as exc:
                chunk = self._empty_read(exc)
            if chunk:
                self._empty_reads = 0
                self._split(chunk)
                continue
            if timeout is not None and time.monotonic() >= deadline_s:
                return None

    def _empty_read(self, exc: serial.SerialException) -> bytes:
        """pyserial calls a read that finds no data after select said ready a disconnect. On a
        pseudo-terminal that also happens once when the adapter flushes its queue as it opens
        (a reset then failed reading 0x1000); only a run of them is a lost device."""
        self._empty_reads += 1
        if "returned no data" not in str(exc) or self._empty_reads > MAX_EMPTY_READS:
            raise exc
        time.sleep(0.001)
        return b""

    def _split(self, chunk: bytes) -> None:
        start = 0
        lines = []
        for i, byte in enumerate(chunk):
            if byte in TERMINATORS:
                self._buffer.extend(chunk[start:i + 1])
                lines.append(self._buffer.decode("ascii", "replace"))
                self._buffer.clear()
                start = i + 1
        self._buffer.extend(chunk[start:])
        if len(self._buffer) > MAX_LINE_BYTES:  # no terminator where one must be: garbage
            self._bad(self._buffer.decode("ascii", "replace"))
            self._buffer.clear()
        with self._line_lock:
            self._lines.extend(lines)

    def _bad(self, line: str) -> None:
        self.bad_lines += 1
        self.last_bad_line = line[:MAX_LINE_BYTES]

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            msg, filtered = super()._recv_internal(timeout)
        except (ValueError, IndexError) as exc:  # a garbled line: one frame lost
            self._bad(f"{exc}")
            return None, False
        if msg is not None and not msg.is_remote_frame and len(msg.data) != msg.dlc:
            self._bad(f"{msg.dlc} data bytes announced, {len(msg.data)} received")  # cut short
            return None, False
        return msg, filtered

    def behind(self) -> bool:
        """Lines or bytes from the adapter not yet handed to the receivers: a heartbeat may be
        among them, so no drive's heartbeat is judged late now."""
        with self._line_lock:
            if self._lines:
                return True
        try:
            return self.serialPortOrig.in_waiting > 0
        except OSError:
            return False

    def flush(self) -> None:
        with self._line_lock:
            self._lines.clear()
        super().flush()
