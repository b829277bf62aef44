"""The `serial` backend: a bit-pattern pulse card on a serial link (pyserial, protocol.py)."""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import numpy as np

from controller.config import MachineConfig
from controller.outputs import OutputImage
from drivers.at_speed_input import AtSpeedInput
from drivers.base import CardStatus, Drive, Feedback
from drivers.errors import BadFrameError, DriveError, LostCommunicationError
from drivers.io_peer import switch_name
from drivers.port_lock import device_key
from drivers.serial import homing, take_back
from drivers.serial import protocol as p

_BITS = ((p.ST_UNDERRUN, CardStatus.UNDERRUN), (p.ST_BAD_FRAME, CardStatus.BAD_FRAME),
         (p.ST_SEQ_GAP, CardStatus.BAD_FRAME), (p.ST_DRIVE_FAULT, CardStatus.FAULT),
         (p.ST_FOLLOWING_ERROR, CardStatus.FOLLOWING_ERROR))


class SerialCard(Drive, AtSpeedInput):
    """Streams one sample frame per period T to the card; a reader thread decodes its reports.

    Options: port (required), baudrate (115200), status_period_s (0.010, the card's report
    period), fifo_frames (256, the capacity the card must report), link_timeout_s (10 status
    periods, at least 0.1 s: no valid report for that long is a lost link; a closed port is
    seen at once), reply_timeout_s (0.5, reset and
    probe), poll_period_s (0.02: a status request this often, whose reply time is the round
    trip of link_stats()), realtime (True; virtual time is refused: the card has its own clock).
    open() resets the card (flags latched by an earlier session are cleared, its FIFO emptied;
    the step counters are kept) and checks the capacity and axis count it reports. The FIFO
    level between reports is estimated from the last report, the frames written since the
    card's last received sample, and the periods elapsed since the report arrived.
    """

    OPTIONS = frozenset({"port", "baudrate", "status_period_s", "fifo_frames", "link_timeout_s",
                         "reply_timeout_s", "poll_period_s", "realtime"})
    at_speed_input_name = "serial card, status io bit 9 AT_SPEED"

    def __init__(self, config: MachineConfig, **options: Any) -> None:
        super().__init__(config, **options)
        if not options.get("realtime", True):
            raise DriveError("serial: the card clocks frames in real time; virtual time "
                             "(--virtual-time, realtime=False) is not available")
        if not isinstance(options.get("port"), str) or not options["port"]:
            raise DriveError("serial: drive option 'port' (the card's device path) is required")
        self.port: str = options["port"]
        self.baudrate = int(self._number("baudrate", 115200))
        self.period_s = config.sample_period_s
        self.status_period_s = self._number("status_period_s", 0.010)
        self.capacity = int(self._number("fifo_frames", 256))
        # Not 3 periods: a loaded PC starves a pty's or USB stack's worker for 50-100 ms at
        # times (bench/drive_serial.py --load), which would be a false "lost link" fault.
        self.link_timeout_s = self._number("link_timeout_s", max(0.1, 10 * self.status_period_s))
        self.reply_timeout_s = self._number("reply_timeout_s", 0.5)
        self.poll_period_s = self._number("poll_period_s", 0.02)
        self._cond = threading.Condition()
        self._ser: Any = None
        self._reader: threading.Thread | None = None
        self._stop = threading.Event()
        self._init_link()

    def _number(self, key: str, default: float) -> float:
        value = self.options.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float) or value <= 0:
            raise DriveError(f"serial: drive option {key!r} must be a positive number, "
                             f"got {value!r}")
        return float(value)

    def _init_link(self) -> None:
        self._decoder = p.Decoder(p.CARD_SYNC)
        self._lost: str | None = None
        self._last: p.Status | None = None
        self._last_rx_s = 0.0
        self._synced = False
        self._written = 0  # frames written since open: the stream index of the next one
        self._base = 0  # wire seq of stream index 0
        self._rx_idx = self._row_idx = -1
        self._cleared_idx = -1  # frames up to here were executed or discarded by a reset
        self._rows: list[tuple[int, tuple[int, ...], tuple[int, ...]]] = []
        self._token = 0
        self._sent_at: dict[int, float] = {}
        self._replies: dict[int, p.Status] = {}
        self._waiting: set[int] = set()  # tokens whose reply someone waits for
        self._rtt_s: deque[float] = deque(maxlen=100000)
        self._next_poll_s = 0.0
        self._status_frames = 0
        self._max_gap_s = 0.0
        self._stream_open = False  # samples sent since the last end of stream (or reset)

    # -- link -------------------------------------------------------------------------------
    def _connect(self) -> None:
        import serial  # late: pyserial is only needed by this backend

        self._init_link()
        try:
            self._ser = serial.Serial(self.port, self.baudrate, timeout=0.05,
                                      write_timeout=max(0.1, self.link_timeout_s))
            self._ser.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DriveError(f"serial port {self.port}: {exc}") from exc
        self._stop.clear()
        self._reader = threading.Thread(target=self._read_loop, name="serialcard-rx",
                                        daemon=True)
        self._reader.start()

    def _disconnect(self) -> None:
        self._stop.set()
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.cancel_read()
            except Exception:  # noqa: BLE001 (a dead port: nothing left to cancel)
                pass
        if self._reader is not None:
            self._reader.join(timeout=1.0)
            self._reader = None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: BLE001
                pass

    def _read_loop(self) -> None:
        ser = self._ser
        while not self._stop.is_set():
            try:
                data = ser.read(ser.in_waiting or 1)
            except Exception as exc:  # noqa: BLE001 (SerialException, OSError, closed port)
                if not self._stop.is_set():
                    self._mark_lost(f"serial link to the card on {self.port} lost: {exc}")
                return
            if data:
                now_s = time.monotonic()
                for frame in self._decoder.feed(data):
                    if isinstance(frame, p.Status):
                        self._on_status(frame, now_s)

    def _mark_lost(self, message: str) -> None:
        with self._cond:
            if self._lost is None:
                self._lost = message
            self._cond.notify_all()

    def _unwrap(self, wire: int) -> int:
        """Stream index of a 16-bit wire seq: the latest one not after the last frame written."""
        last = self._written - 1
        return last - ((last - (wire - self._base)) % p.SEQ_MOD)

    def _on_status(self, s: p.Status, now_s: float) -> None:
        with self._cond:
            self._status_frames += 1
            if s.reply_to and s.reply_to in self._sent_at:
                self._rtt_s.append(now_s - self._sent_at.pop(s.reply_to))
                if s.reply_to in self._waiting:
                    self._replies[s.reply_to] = s
            if self._synced:
                self._rx_idx = self._unwrap(s.rx_seq)
                exec_idx = self._unwrap(s.exec_seq)
                if exec_idx > self._row_idx and exec_idx >= 0:
                    prev = exec_idx - 1
                    if s.latched & p.ST_EXECUTED and prev > self._row_idx and prev >= 0:
                        self._rows.append((prev, tuple(np.subtract(s.commanded,
                                                                   s.commanded_delta)),
                                           tuple(np.subtract(s.encoder, s.encoder_delta))))
                    self._rows.append((exec_idx, s.commanded, s.encoder))
                    self._row_idx = exec_idx
            if self._last is not None:
                self._max_gap_s = max(self._max_gap_s, now_s - self._last_rx_s)
            self._last, self._last_rx_s = s, now_s
            self._cond.notify_all()

    def _write(self, data: bytes) -> None:
        """Write or mark the link lost (the next feedback()/status() raises, never a hang)."""
        if self._lost is not None or self._ser is None:
            return
        try:
            self._ser.write(data)
        except Exception as exc:  # noqa: BLE001 (SerialException, SerialTimeoutException, OSError)
            self._mark_lost(f"serial link to the card on {self.port} lost on write: {exc}")

    def _request(self, encode: Any, what: str) -> p.Status:
        """Send a reset or status request and wait for its reply."""
        with self._cond:
            self._token = self._token % (p.SEQ_MOD - 1) + 1
            token = self._token
            self._sent_at[token] = time.monotonic()
            self._waiting.add(token)
        self._write(encode(token))
        deadline_s = time.monotonic() + self.reply_timeout_s
        with self._cond:
            while token not in self._replies and self._lost is None:
                left_s = deadline_s - time.monotonic()
                if left_s <= 0:
                    break
                self._cond.wait(left_s)
            self._waiting.discard(token)
            if self._lost is not None:
                raise LostCommunicationError(self._lost)
            if token not in self._replies:
                self._sent_at.pop(token, None)
                raise LostCommunicationError(
                    f"no answer to a {what} from the card on {self.port} within "
                    f"{self.reply_timeout_s:g} s ({self._decoder.crc_errors} frames with bad "
                    "CRC)")
            return self._replies.pop(token)

    def _check_link(self) -> None:
        if self._lost is None and self._last is not None:
            silent_s = time.monotonic() - self._last_rx_s
            # A late motion cycle can starve our own reader: bytes waiting are not silence.
            if silent_s > self.link_timeout_s and not self._waiting_bytes():
                self._mark_lost(
                    f"no valid status from the card on {self.port} for {silent_s * 1e3:.0f} ms "
                    f"(limit {self.link_timeout_s * 1e3:.0f} ms; {self._decoder.crc_errors} "
                    "status frames with bad CRC)")
        if self._lost is not None:
            raise LostCommunicationError(self._lost)

    def _waiting_bytes(self) -> bool:
        try:
            return self._ser is not None and self._ser.in_waiting > 0
        except Exception:  # noqa: BLE001
            return False

    def _poll(self) -> None:
        now_s = time.monotonic()
        if self.poll_period_s > 0 and now_s >= self._next_poll_s:
            self._next_poll_s = now_s + self.poll_period_s
            with self._cond:
                self._token = self._token % (p.SEQ_MOD - 1) + 1
                self._sent_at[self._token] = now_s
                token = self._token
            self._write(p.encode_status_request(token))

    def _sync(self, reply: p.Status) -> None:
        """After a reset reply: the next frame written continues the card's numbering."""
        with self._cond:
            self._base = (reply.rx_seq + 1 - self._written) % p.SEQ_MOD
            self._rx_idx = self._written - 1
            self._row_idx = max(self._row_idx, self._written - 1)
            self._cleared_idx = self._written - 1
            self._stream_open = False
            self._synced = True

    def _check_capacity(self, reply: p.Status) -> None:
        if reply.fifo_capacity != self.capacity or len(reply.commanded) != self.n_axes:
            raise DriveError(f"serial card on {self.port} reports a {reply.fifo_capacity}-frame "
                             f"FIFO and {len(reply.commanded)} axes; the config says "
                             f"fifo_frames {self.capacity} and {self.n_axes} axes")

    # -- hooks ------------------------------------------------------------------------------
    def _lock_key(self) -> str:
        return device_key(self.port)

    def _open(self) -> None:
        self._connect()
        try:
            reply = self._request(p.encode_reset, "reset")
            self._check_capacity(reply)
        except DriveError:
            self._disconnect()
            raise
        self._sync(reply)

    def _probe(self) -> None:
        self._connect()
        try:
            self._check_capacity(self._request(p.encode_status_request, "status request"))
        except LostCommunicationError as exc:
            raise DriveError(f"no serial card answering on {self.port}: {exc}") from exc
        finally:
            self._disconnect()

    def _close(self) -> None:
        self._disconnect()

    def _send_frames(self, frames: np.ndarray, end_of_stream: bool) -> None:
        n = frames.shape[0]
        if n and self._estimate_level() + n > self.capacity:
            raise BadFrameError(f"serial card FIFO would overflow: about "
                                f"{self._estimate_level()} + {n} > {self.capacity} frames")
        seq0 = self._base + self._written
        rows = frames.tolist()
        data = b"".join(p.encode_sample(seq0 + i, row, end_of_stream and i == n - 1)
                        for i, row in enumerate(rows))
        if end_of_stream and not n:
            data = p.encode_end()
        with self._cond:
            self._written += n
            self._stream_open = not end_of_stream and (bool(n) or self._stream_open)
        self._write(data)

    def _recall_frames(self, n: int, keep: int) -> int:
        return take_back.recall(self, n, keep)

    def _estimate_level(self) -> int:
        with self._cond:
            s = self._last
            if s is None:
                return 0
            in_flight = self._written - (self._rx_idx + 1)
            clocked = int((time.monotonic() - self._last_rx_s) / self.period_s)
            level = max(0, s.fifo_level + in_flight - clocked)
            done_idx = max(self._unwrap(s.exec_seq), self._cleared_idx)
            if level == 0 and done_idx < self._written - 1 \
                    and not s.latched & p.ST_LATCHED:
                level = 1  # not confirmed executed yet: never report empty early
            return level

    def _fifo_level(self) -> int:
        self._check_link()
        self._poll()
        return self._estimate_level()

    def _fifo_capacity(self) -> int:
        return self.capacity

    def _read_feedback(self) -> Feedback:
        self._check_link()
        with self._cond:
            rows, self._rows = self._rows, []
        if not rows:
            empty = np.zeros((0, self.n_axes), dtype=np.int64)
            return Feedback(np.zeros(0, dtype=np.int64), empty, empty.copy())
        return Feedback(np.array([r[0] for r in rows], dtype=np.int64),
                        np.array([r[1] for r in rows], dtype=np.int64),
                        np.array([r[2] for r in rows], dtype=np.int64))

    def _read_position(self) -> tuple[np.ndarray, np.ndarray]:
        self._check_link()
        s = self._last
        assert s is not None  # open() waited for the reset reply
        return np.array(s.commanded, dtype=np.int64), np.array(s.encoder, dtype=np.int64)

    def _read_status(self) -> CardStatus:
        self._check_link()
        latched = self._last.latched if self._last is not None else 0
        status = CardStatus.OK
        for bit, flag in _BITS:
            if latched & bit:
                status |= flag
        return status

    def _fault_message(self) -> str:
        s = self._last
        if s is None:
            return self._lost or ""
        names = self.config.axis_names
        axis = names[s.fault_axis].upper() if s.fault_axis < len(names) else f"#{s.fault_axis}"
        exec_idx = self._unwrap(s.exec_seq)
        parts = {p.ST_UNDERRUN: "card FIFO underrun: frames ran out mid-program after frame "
                                f"{exec_idx}; card stopped",
                 p.ST_BAD_FRAME: f"serial card on {self.port} received a bad frame (bad CRC, "
                                 "length, pulse count or FIFO overflow); card stopped",
                 p.ST_SEQ_GAP: f"serial card on {self.port} saw a sequence gap after frame "
                               f"{self._unwrap(s.rx_seq)} (a frame was lost); card stopped",
                 p.ST_DRIVE_FAULT: f"{axis} axis drive fault 0x{s.fault_code:04X}",
                 p.ST_FOLLOWING_ERROR: f"{axis} axis following error (card limit)"}
        text = "; ".join(msg for bit, msg in parts.items() if s.latched & bit)
        return "; ".join(t for t in (text, self._lost) if t)

    def _stream_active(self) -> bool:
        return self._stream_open or self._fifo_level() > 0

    def _home(self, axes: tuple[int, ...], timeout_s: float) -> None:
        homing.home(self, axes, timeout_s)

    def _reset(self) -> None:
        self._check_link()
        self._sync(self._request(p.encode_reset, "reset"))
        with self._cond:
            self._rows = []

    def _disable(self) -> None:
        """DISABLE: the card drops its FIFO and turns its amplifiers off until a RESET."""
        self._check_link()
        self._sync(self._request(p.encode_disable, "disable"))
        with self._cond:
            self._rows = []

    def _estop_input(self) -> bool:
        s = self._last  # the card reports its input in every status frame (io byte)
        return s is not None and bool(s.io & p.IO_ESTOP_INPUT)

    def _probe_input(self) -> bool:
        s = self._last  # in every status frame too (io bit PROBE_INPUT)
        return s is not None and bool(s.io & p.IO_PROBE_INPUT)

    def at_speed_input(self) -> bool:
        return self._last is not None and bool(self._last.io & p.IO_AT_SPEED)  # io bit 9

    def _limit_input(self) -> str | None:
        s = self._last  # the limit switches ride in the same io word
        tripped = None if s is None else p.limit_of(s.io, self.n_axes)
        return None if tripped is None else switch_name(self.config.axis_names[tripped[0]],
                                                     tripped[1])

    def _write_outputs(self, image: OutputImage) -> None:
        """An OUTPUTS frame, confirmed by the card's status reply."""
        self._check_link()
        self._sync(self._request(lambda token: p.encode_outputs(token, image.bits,
                                                                image.analog), "outputs"))

    # -- measurements -----------------------------------------------------------------------
    def link_stats(self) -> dict[str, Any]:
        """Round trip = a status request written by this process -> its reply decoded by the
        reader thread (seconds, one per answered request); plus frame and error counters."""
        with self._cond:
            return {"rtt_s": list(self._rtt_s), "status_frames": self._status_frames,
                    "max_status_gap_s": self._max_gap_s,
                    "crc_errors": self._decoder.crc_errors,
                    "garbage_bytes": self._decoder.garbage_bytes,
                    "frames_written": self._written}
