"""A fake slcan (Lawicel) USB-CAN adapter on a pseudo-terminal, bridged to a python-can bus."""

from __future__ import annotations

import os
import select
import termios
import threading
import time
import tty

import can

WRITE_WAIT_S = 1.0  # the host read nothing for this long: it is gone, drop whole frames
VERSION_REPLIES = {"V": b"V1013\r", "v": b"vSTM32\r", "N": b"NA123\r", "F": b"F00\r"}


def encode(msg: can.Message) -> bytes:
    """python-can message -> Lawicel line (t/T data, r/R remote)."""
    dlc = msg.dlc
    if msg.is_extended_id:
        head = f"{'R' if msg.is_remote_frame else 'T'}{msg.arbitration_id:08X}{dlc}"
    else:
        head = f"{'r' if msg.is_remote_frame else 't'}{msg.arbitration_id:03X}{dlc}"
    body = "" if msg.is_remote_frame else bytes(msg.data[:dlc]).hex().upper()
    return (head + body + "\r").encode("ascii")


def decode(line: str) -> can.Message:
    """Lawicel t/T/r/R line (without the CR) -> python-can message; ValueError if malformed."""
    kind = line[0]
    id_len = 8 if kind in "TR" else 3
    can_id = int(line[1:1 + id_len], 16)
    dlc = int(line[1 + id_len])
    if dlc > 8:
        raise ValueError(f"bad DLC {dlc}")
    remote = kind in "rR"
    data = b"" if remote else bytes.fromhex(line[2 + id_len:2 + id_len + 2 * dlc])
    if len(data) != (0 if remote else dlc):
        raise ValueError("short data")
    return can.Message(arbitration_id=can_id, is_extended_id=kind in "TR",
                       is_remote_frame=remote, dlc=dlc, data=data)


class SlcanPty:
    """Opens a pty (raw); the controller opens `path` with interface="slcan" exactly as it
    would open a CANable. Frames flow only between the adapter's O (open) and C (close)
    commands; on O, bytes the host never read are discarded (no stale frames)."""

    def __init__(self, channel: str, interface: str = "virtual") -> None:
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        os.set_blocking(self.master_fd, False)
        self.path = os.ttyname(self.slave_fd)
        self.bus = can.Bus(interface=interface, channel=channel, receive_own_messages=False)
        self.opened = False
        self.frames_from_host = self.frames_to_host = self.dropped = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._from_host, name="slcan-rx", daemon=True),
                         threading.Thread(target=self._to_host, name="slcan-tx", daemon=True)]

    def host_pending(self) -> bool:
        """Bytes from the host not yet read: the host is not silent, we are behind."""
        readable, _, _ = select.select([self.master_fd], [], [], 0)
        return bool(readable)

    def start(self) -> None:
        for thread in self._threads:
            thread.start()

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            if thread.is_alive():
                thread.join(timeout=1.0)
        self.bus.shutdown()
        for fd in (self.master_fd, self.slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass

    def _write(self, data: bytes) -> None:
        """One whole line to the host, like a USB adapter's buffer: wait while the host is
        slow (a starved host reads late, it loses nothing), drop the line only when the host
        has read nothing for WRITE_WAIT_S, and never cut a line once begun (half a line
        reached the host as garbage, and a lost TPDO as a wrong pairing)."""
        with self._lock:
            begun = False
            deadline_s = time.monotonic() + WRITE_WAIT_S
            while data and not self._stop.is_set():
                try:
                    written = os.write(self.master_fd, data)
                except BlockingIOError:
                    written = 0
                except OSError:
                    self.dropped += 1
                    return
                if written:
                    data, begun = data[written:], True
                    deadline_s = time.monotonic() + WRITE_WAIT_S
                    continue
                if not begun and time.monotonic() > deadline_s:
                    self.dropped += 1  # the host is not reading: this frame is lost whole
                    return
                select.select([], [self.master_fd], [], 0.05)

    def _from_host(self) -> None:
        buf = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master_fd], [], [], 0.1)
            if not ready:
                continue
            try:
                buf += os.read(self.master_fd, 4096)
            except (BlockingIOError, OSError):
                continue
            while b"\r" in buf:
                line, _, buf = buf.partition(b"\r")
                self._write(self._command(line.decode("ascii", "replace").strip("\n")))

    def _command(self, line: str) -> bytes:
        if not line:
            return b"\r"
        kind = line[0]
        if kind in "tTrR":
            try:
                msg = decode(line)
            except (ValueError, IndexError):
                return b"\a"
            if self.opened:
                self.frames_from_host += 1
                self.bus.send(msg)
            return b"z\r" if kind in "tr" else b"Z\r"
        if kind in "OL":
            termios.tcflush(self.slave_fd, termios.TCIFLUSH)
            self.opened = True
            return b"\r"
        if kind == "C":
            self.opened = False
            return b"\r"
        if kind in VERSION_REPLIES:
            return VERSION_REPLIES[kind]
        if kind in "SsZMmXWQ":
            return b"\r"
        return b"\a"

    def _to_host(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.1)
            if msg is None or not self.opened or msg.is_error_frame:
                continue
            self.frames_to_host += 1
            self._write(encode(msg))
