"""The serial pulse card's binary wire protocol: frame encode/decode and a resynchronising decoder.

Every frame is SYNC, TYPE, LEN, PAYLOAD (LEN bytes), CRC16, little-endian throughout. The CRC is
CRC-16/CCITT-FALSE (`binascii.crc_hqx(data, 0xFFFF)`) over SYNC..PAYLOAD, sent low byte first.
Host -> card frames start with 0xA5, card -> host frames with 0x5A. See docs/serial-protocol.md.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass

HOST_SYNC = 0xA5  # host -> card
CARD_SYNC = 0x5A  # card -> host

T_SAMPLE8 = 0x01  # one sample, int8 pulse counts per axis
T_SAMPLE16 = 0x02  # one sample, int16 pulse counts per axis
T_RESET = 0x10  # clear latched flags, discard the FIFO, answer with a status frame
T_STATUS_REQUEST = 0x11  # answer with a status frame now
T_END = 0x12  # end of stream after the samples already sent (no new sample)
T_HOME = 0x13  # run the homing sequence of the axes in a mask (answered with a status frame)
T_DISABLE = 0x14  # e-stop: discard the FIFO, amplifiers off until a RESET (answered by status)
T_OUTPUTS = 0x15  # set the digital outputs and analog channels now (answered by status)
T_RECALL = 0x16  # take back the queued samples from a seq on, if `keep` stay (answered by status)
T_STATUS = 0x80  # card -> host status report

FLAG_END_OF_STREAM = 0x01  # sample flag: the last frame of a program

# Latched status bits (cleared only by a reset frame).
ST_UNDERRUN = 0x01  # FIFO ran empty mid-stream; the card stopped
ST_BAD_FRAME = 0x02  # a frame with a bad CRC, a bad length or too many pulses; or FIFO overflow
ST_SEQ_GAP = 0x04  # a sample's sequence number was not the previous one + 1
ST_DRIVE_FAULT = 0x08  # an axis amplifier faulted (fault_axis, fault_code say which)
ST_FOLLOWING_ERROR = 0x10  # the card's own following-error limit tripped (fault_axis)
ST_LATCHED = 0x1F
ST_HOME_FAILED = 0x20  # the last HOME failed (fault_axis, fault_code = HOME_*); no halt;
#                        cleared by the next HOME or a RESET
ST_HOMING = 0x40  # not latched: a homing sequence is running
ST_EXECUTED = 0x80  # not latched: the last clock tick executed sample exec_seq

# The status frame's io word, 16 bits little-endian (not latched: what is true now).
IO_DISABLED = 0x01  # amplifiers off (a DISABLE frame, until a RESET with the input closed)
IO_ESTOP_INPUT = 0x02  # the card's e-stop input is open (tripped)
IO_LIMIT_NEG = 0x04  # axis i's negative limit switch is open: this bit shifted left by 2 i
IO_LIMIT_POS = 0x08  # axis i's positive limit switch is open: this bit shifted left by 2 i
IO_PROBE_INPUT = 0x100  # the probe input (G38) is in contact (the io word's second byte)
IO_AT_SPEED = 0x200  # the spindle's at-speed input is true (io.spindle.at_speed_input)
N_ANALOG = 4  # analog channels in an OUTPUTS frame

# fault_code of ST_HOME_FAILED (a drive fault during homing is ST_DRIVE_FAULT instead)
HOME_NOT_FOUND = 1  # no switch within the search limit
HOME_BUSY = 2  # refused: samples queued, a stream not ended, a halted card or a homing running
HOME_BAD_REQUEST = 3  # refused: a direction or speed the card cannot run
HOME_NO_RELEASE = 4  # the switch did not release when backing off
HOME_REASONS = {HOME_NOT_FOUND: "home switch not found within the search limit",
                HOME_BUSY: "refused by the card: not idle (samples queued, a stream not "
                           "ended, halted, or homing already)",
                HOME_BAD_REQUEST: "refused by the card: bad homing parameters",
                HOME_NO_RELEASE: "the home switch does not release"}

AXES_ALLOWED = (2, 3)
SEQ_MOD = 1 << 16
_HEADER = 3  # sync, type, len
_CRC = 2
_SAMPLE_FIXED = 3  # seq u16, flags u8
_CONTROL_LEN = 2  # token u16
_OUTPUTS_FMT = f"<HH{N_ANALOG}f"  # token, digital bits, analog channels (float32)
_OUTPUTS_LEN = struct.calcsize(_OUTPUTS_FMT)  # 20 bytes
_RECALL_FMT = "<HHH"  # token, the first seq taken back, samples that must stay queued
_RECALL_LEN = struct.calcsize(_RECALL_FMT)  # 6 bytes
_STATUS_FMT = "<HHHBBHHH"
_STATUS_FIXED = struct.calcsize(_STATUS_FMT)  # 14 bytes, then the axes, then the io word
_STATUS_TAIL = 2  # io, uint16 (limit switches of 3 axes fill its first byte)
_STATUS_AXIS = struct.calcsize("<iihh")  # 12 bytes per axis
_HOME_FIXED = struct.calcsize("<HB")  # token, axis mask
_HOME_AXIS_FMT = "<bBIIIiiI"
_HOME_AXIS = struct.calcsize(_HOME_AXIS_FMT)  # 26 bytes per axis


class ProtocolError(ValueError):
    """A frame that cannot be encoded (wrong axis count, value out of range)."""


@dataclass(frozen=True)
class Sample:
    """One sample period of pulse counts; seq is the 16-bit wire sequence number."""

    seq: int
    counts: tuple[int, ...]
    end_of_stream: bool = False


@dataclass(frozen=True)
class Reset:
    token: int = 0


@dataclass(frozen=True)
class Disable:
    token: int = 0


@dataclass(frozen=True)
class StatusRequest:
    token: int = 0


@dataclass(frozen=True)
class End:
    token: int = 0


@dataclass(frozen=True)
class Status:
    """Card report: counters are after the last executed sample (exec_seq); *_delta is the
    change over that last sample, so the host also knows the sample before it."""

    reply_to: int  # token of the request answered, 0 for a periodic report
    fifo_level: int
    fifo_capacity: int
    latched: int  # ST_* bits (ST_EXECUTED is not latched)
    fault_axis: int
    fault_code: int
    rx_seq: int  # last sample received (queued), 16-bit
    exec_seq: int  # last sample executed, 16-bit
    commanded: tuple[int, ...]  # step counters, int32
    encoder: tuple[int, ...]  # encoder counts, int32
    commanded_delta: tuple[int, ...]  # int16
    encoder_delta: tuple[int, ...]  # int16
    io: int = 0  # IO_* bits


@dataclass(frozen=True)
class HomeAxis:
    """One axis's homing parameters in pulses (ignored unless its bit is in the mask)."""

    direction: int = 0  # -1 or +1: the search direction
    use_index: bool = False  # latch on the index mark after the switch edge
    search_pps: int = 0  # search speed, pulses/s (also the back-off and final moves)
    latch_pps: int = 0  # latch speed, pulses/s
    accel_pps2: int = 0  # acceleration, pulses/s^2
    home_pulses: int = 0  # the point found reads this
    final_pulses: int = 0  # then the axis moves here
    search_limit_pulses: int = 0  # no switch within this distance: HOME_NOT_FOUND


@dataclass(frozen=True)
class Home:
    token: int
    mask: int  # bit i: axis i homes
    axes: tuple[HomeAxis, ...]  # one per axis


@dataclass(frozen=True)
class Outputs:
    """Digital output i is bit i of `bits`; analog[c] is channel c (the card's units)."""

    token: int
    bits: int
    analog: tuple[float, ...] = (0.0,) * N_ANALOG


@dataclass(frozen=True)
class Recall:
    """Take back the samples queued from `first_seq` through the last received, all or none:
    refused when one of them has executed, ends the stream, or fewer than `keep` would stay."""

    token: int
    first_seq: int
    keep: int


def limit_bits(axis: int, direction: int) -> int:
    """The io bit of axis `axis`'s limit switch on the side `direction` (+1, -1)."""
    return (IO_LIMIT_POS if direction > 0 else IO_LIMIT_NEG) << (2 * axis)


def limit_of(io: int, n_axes: int) -> tuple[int, int] | None:
    """The first open limit switch in an io byte: (axis, +1 or -1), or None."""
    for axis in range(n_axes):
        for direction in (-1, 1):
            if io & limit_bits(axis, direction):
                return axis, direction
    return None


Frame = Sample | Reset | StatusRequest | End | Status | Home | Disable | Outputs | Recall
_CONTROL = {T_RESET: Reset, T_STATUS_REQUEST: StatusRequest, T_END: End, T_DISABLE: Disable}


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), via binascii."""
    return binascii.crc_hqx(data, 0xFFFF)


def _wrap(sync: int, ftype: int, payload: bytes) -> bytes:
    body = bytes((sync, ftype, len(payload))) + payload
    return body + struct.pack("<H", crc16(body))


def _check_axes(n: int) -> None:
    if n not in AXES_ALLOWED:
        raise ProtocolError(f"{n} axes: the protocol carries 2 or 3")


def encode_sample(seq: int, counts: tuple[int, ...] | list[int], end_of_stream: bool = False
                  ) -> bytes:
    """int8 counts when every count fits in [-128, 127], int16 otherwise."""
    _check_axes(len(counts))
    values = [int(c) for c in counts]
    if all(-128 <= c <= 127 for c in values):
        ftype, fmt = T_SAMPLE8, "b"
    elif all(-32768 <= c <= 32767 for c in values):
        ftype, fmt = T_SAMPLE16, "h"
    else:
        raise ProtocolError(f"pulse counts {values} do not fit in int16")
    flags = FLAG_END_OF_STREAM if end_of_stream else 0
    payload = struct.pack(f"<HB{len(values)}{fmt}", seq % SEQ_MOD, flags, *values)
    return _wrap(HOST_SYNC, ftype, payload)


def encode_reset(token: int = 0) -> bytes:
    return _wrap(HOST_SYNC, T_RESET, struct.pack("<H", token % SEQ_MOD))


def encode_status_request(token: int = 0) -> bytes:
    return _wrap(HOST_SYNC, T_STATUS_REQUEST, struct.pack("<H", token % SEQ_MOD))


def encode_end(token: int = 0) -> bytes:
    return _wrap(HOST_SYNC, T_END, struct.pack("<H", token % SEQ_MOD))


def encode_disable(token: int = 0) -> bytes:
    return _wrap(HOST_SYNC, T_DISABLE, struct.pack("<H", token % SEQ_MOD))


def encode_home(token: int, mask: int, axes: tuple[HomeAxis, ...] | list[HomeAxis]) -> bytes:
    _check_axes(len(axes))
    payload = struct.pack("<HB", token % SEQ_MOD, mask & ((1 << len(axes)) - 1))
    for a in axes:
        try:
            payload += struct.pack(_HOME_AXIS_FMT, a.direction, 1 if a.use_index else 0,
                                   a.search_pps, a.latch_pps, a.accel_pps2, a.home_pulses,
                                   a.final_pulses, a.search_limit_pulses)
        except struct.error as exc:
            raise ProtocolError(f"home parameters out of range: {a}: {exc}") from exc
    return _wrap(HOST_SYNC, T_HOME, payload)


def encode_outputs(token: int, bits: int, analog: tuple[float, ...] | list[float]) -> bytes:
    if len(analog) != N_ANALOG:
        raise ProtocolError(f"outputs: {N_ANALOG} analog channels, got {len(analog)}")
    try:
        payload = struct.pack(_OUTPUTS_FMT, token % SEQ_MOD, bits, *analog)
    except struct.error as exc:
        raise ProtocolError(f"outputs out of range: bits {bits}: {exc}") from exc
    return _wrap(HOST_SYNC, T_OUTPUTS, payload)


def encode_recall(token: int, first_seq: int, keep: int) -> bytes:
    if not 0 <= keep < SEQ_MOD:
        raise ProtocolError(f"recall: keep {keep} out of range")
    payload = struct.pack(_RECALL_FMT, token % SEQ_MOD, first_seq % SEQ_MOD, keep)
    return _wrap(HOST_SYNC, T_RECALL, payload)


def encode_status(s: Status) -> bytes:
    n = len(s.commanded)
    _check_axes(n)
    if not (len(s.encoder) == len(s.commanded_delta) == len(s.encoder_delta) == n):
        raise ProtocolError("status: per-axis fields must have one value per axis")
    payload = struct.pack(_STATUS_FMT, s.reply_to % SEQ_MOD, s.fifo_level, s.fifo_capacity,
                          s.latched, s.fault_axis, s.fault_code, s.rx_seq % SEQ_MOD,
                          s.exec_seq % SEQ_MOD)
    for i in range(n):
        payload += struct.pack("<iihh", s.commanded[i], s.encoder[i],
                               _clamp16(s.commanded_delta[i]), _clamp16(s.encoder_delta[i]))
    return _wrap(CARD_SYNC, T_STATUS, payload + struct.pack("<H", s.io & 0xFFFF))


def encode(frame: Frame) -> bytes:
    if isinstance(frame, Sample):
        return encode_sample(frame.seq, frame.counts, frame.end_of_stream)
    if isinstance(frame, Reset):
        return encode_reset(frame.token)
    if isinstance(frame, StatusRequest):
        return encode_status_request(frame.token)
    if isinstance(frame, End):
        return encode_end(frame.token)
    if isinstance(frame, Disable):
        return encode_disable(frame.token)
    if isinstance(frame, Home):
        return encode_home(frame.token, frame.mask, frame.axes)
    if isinstance(frame, Outputs):
        return encode_outputs(frame.token, frame.bits, frame.analog)
    if isinstance(frame, Recall):
        return encode_recall(frame.token, frame.first_seq, frame.keep)
    return encode_status(frame)


def _clamp16(v: int) -> int:
    return max(-32768, min(32767, int(v)))


def _plausible(sync: int, ftype: int, length: int) -> bool:
    """Whether a header can start a frame (lets the decoder skip false syncs quickly)."""
    if sync == HOST_SYNC:
        if ftype in (T_SAMPLE8, T_SAMPLE16):
            width = 1 if ftype == T_SAMPLE8 else 2
            return any(length == _SAMPLE_FIXED + n * width for n in AXES_ALLOWED)
        if ftype == T_HOME:
            return any(length == _HOME_FIXED + n * _HOME_AXIS for n in AXES_ALLOWED)
        if ftype == T_OUTPUTS:
            return length == _OUTPUTS_LEN
        if ftype == T_RECALL:
            return length == _RECALL_LEN
        return ftype in _CONTROL and length == _CONTROL_LEN
    return ftype == T_STATUS and any(length == _STATUS_FIXED + n * _STATUS_AXIS + _STATUS_TAIL
                                     for n in AXES_ALLOWED)


def decode_payload(ftype: int, payload: bytes) -> Frame:
    """The frame a (type, payload) pair carries; the length must be plausible."""
    if ftype in (T_SAMPLE8, T_SAMPLE16):
        fmt = "b" if ftype == T_SAMPLE8 else "h"
        n = (len(payload) - _SAMPLE_FIXED) // struct.calcsize(fmt)
        seq, flags, *counts = struct.unpack(f"<HB{n}{fmt}", payload)
        return Sample(seq, tuple(counts), bool(flags & FLAG_END_OF_STREAM))
    if ftype in _CONTROL:
        (token,) = struct.unpack("<H", payload)
        return _CONTROL[ftype](token)
    if ftype == T_OUTPUTS:
        token, bits, *analog = struct.unpack(_OUTPUTS_FMT, payload)
        return Outputs(token, bits, tuple(analog))
    if ftype == T_RECALL:
        return Recall(*struct.unpack(_RECALL_FMT, payload))
    if ftype == T_HOME:
        token, mask = struct.unpack_from("<HB", payload)
        n = (len(payload) - _HOME_FIXED) // _HOME_AXIS
        blocks = [struct.unpack_from(_HOME_AXIS_FMT, payload, _HOME_FIXED + i * _HOME_AXIS)
                  for i in range(n)]
        return Home(token, mask, tuple(HomeAxis(b[0], bool(b[1] & 1), *b[2:]) for b in blocks))
    fixed = struct.unpack(_STATUS_FMT, payload[:_STATUS_FIXED])
    n = (len(payload) - _STATUS_FIXED - _STATUS_TAIL) // _STATUS_AXIS
    axes = [struct.unpack_from("<iihh", payload, _STATUS_FIXED + i * _STATUS_AXIS)
            for i in range(n)]
    io = int.from_bytes(payload[-_STATUS_TAIL:], "little")
    return Status(*fixed, *(tuple(a[k] for a in axes) for k in range(4)), io=io)


def decode(data: bytes) -> Frame:
    """Exactly one whole frame; raises ProtocolError if it is not one."""
    if not data or data[0] not in (HOST_SYNC, CARD_SYNC):
        raise ProtocolError(f"not a frame: {data[:8].hex()}")
    dec = Decoder(data[0])
    frames = dec.feed(data)
    if len(frames) != 1 or dec.pending or dec.crc_errors or dec.garbage_bytes:
        raise ProtocolError(f"not one valid frame: {data.hex()}")
    return frames[0]


class Decoder:
    """Incremental: feed() bytes as they arrive, get whole frames. After garbage or a bad CRC
    it drops one byte and looks for the next sync byte, so one bad frame costs one frame."""

    def __init__(self, sync: int) -> None:
        self.sync = sync
        self._buf = bytearray()
        self.crc_errors = 0  # plausible headers whose CRC failed
        self.garbage_bytes = 0  # bytes skipped while looking for a frame
        self.frames = 0

    @property
    def pending(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        out: list[Frame] = []
        buf = self._buf
        while True:
            start = buf.find(self.sync)
            if start < 0:
                self.garbage_bytes += len(buf)
                buf.clear()
                break
            if start:
                self.garbage_bytes += start
                del buf[:start]
            if len(buf) < _HEADER:
                break
            ftype, length = buf[1], buf[2]
            if not _plausible(self.sync, ftype, length):
                self.garbage_bytes += 1
                del buf[:1]
                continue
            total = _HEADER + length + _CRC
            if len(buf) < total:
                break
            (crc,) = struct.unpack_from("<H", buf, _HEADER + length)
            if crc != crc16(bytes(buf[: _HEADER + length])):
                self.crc_errors += 1
                self.garbage_bytes += 1
                del buf[:1]
                continue
            out.append(decode_payload(ftype, bytes(buf[_HEADER: _HEADER + length])))
            self.frames += 1
            del buf[:total]
        return out
