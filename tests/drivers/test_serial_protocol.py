"""The serial card's wire protocol: byte-exact transcripts, decoder resync, CRC rejection."""

from __future__ import annotations

import pytest

from drivers.serial import protocol as p

STATUS = p.Status(reply_to=3, fifo_level=100, fifo_capacity=256,
                  latched=p.ST_UNDERRUN | p.ST_EXECUTED, fault_axis=0, fault_code=0,
                  rx_seq=0x0203, exec_seq=0x0102, commanded=(-21790, 2787),
                  encoder=(-21771, 2790), commanded_delta=(-58, 1), encoder_delta=(-57, 0))

INPUTS = p.Status(0, 0, 256, 0, 0, 0, 1, 1, (1, 2), (3, 4), (0, 0), (0, 0),
                  io=p.IO_ESTOP_INPUT | p.limit_bits(1, -1))  # the e-stop input and Y-

# (frame, exact bytes) -- docs/serial-protocol.md shows the same frames field by field.
TRANSCRIPT: list[tuple[p.Frame, str]] = [
    (p.Sample(5, (3, -4), True), "a5 01 05 0500 01 03 fc ae6b"),
    (p.Sample(0xFFFF, (300, -2, 5)), "a5 02 09 ffff 00 2c01 feff 0500 ad4a"),
    (p.Sample(7, (0, 0)), "a5 01 05 0700 00 00 00 dd63"),
    (p.Reset(0x1234), "a5 10 02 3412 da96"),
    (p.StatusRequest(1), "a5 11 02 0100 7d28"),
    (p.End(2), "a5 12 02 0200 f2e6"),
    (p.Disable(4), "a5 14 02 0400 cd6b"),
    (p.Recall(6, 0x0120, 20), "a5 16 06 0600 2001 1400 8229"),
    (STATUS, "5a 80 28 0300 6400 0001 81 00 0000 0302 0201"
             " e2aaffff f5aaffff c6ff c7ff e30a0000 e60a0000 0100 0000 0000 19f1"),
    (p.Outputs(5, 0x0031, (1000.0, 2.5, 0.0, -1.0)),
     "a5 15 14 0500 3100 00007a44 00002040 00000000 000080bf c147"),
    (INPUTS, "5a 80 28 0000 0000 0001 00 00 0000 0100 0100"
             " 01000000 03000000 0000 0000 02000000 04000000 0000 0000 1200 c8a5"),
]


def test_crc_is_ccitt_false() -> None:
    assert p.crc16(b"123456789") == 0x29B1  # the catalogued check value of CRC-16/CCITT-FALSE


@pytest.mark.parametrize(("frame", "hexbytes"), TRANSCRIPT)
def test_frames_encode_to_exact_bytes_and_back(frame: p.Frame, hexbytes: str) -> None:
    data = bytes.fromhex(hexbytes.replace(" ", ""))
    assert p.encode(frame) == data
    assert p.decode(data) == frame


def test_sample_width_follows_the_counts_and_seq_wraps() -> None:
    assert p.encode_sample(65536 + 7, (0, 0)) == p.encode_sample(7, (0, 0))
    assert p.encode_sample(0, (127, -128))[1] == p.T_SAMPLE8
    assert p.encode_sample(0, (128, 0))[1] == p.T_SAMPLE16
    with pytest.raises(p.ProtocolError, match="int16"):
        p.encode_sample(0, (40000, 0))
    with pytest.raises(p.ProtocolError, match="2 or 3"):
        p.encode_sample(0, (1, 2, 3, 4))


def _stream() -> tuple[bytes, list[p.Frame]]:
    frames = [f for f, _ in TRANSCRIPT if not isinstance(f, p.Status)]
    return b"".join(p.encode(f) for f in frames), frames


def test_decoder_takes_bytes_one_at_a_time() -> None:
    data, frames = _stream()
    dec = p.Decoder(p.HOST_SYNC)
    out = [f for b in data for f in dec.feed(bytes([b]))]
    assert out == frames and dec.garbage_bytes == 0 and dec.crc_errors == 0


def test_decoder_resynchronises_after_garbage() -> None:
    data, frames = _stream()
    noise = bytes([0x00, 0xA5, 0xA5, 0x01, 0xFF, 0x13, 0xA5, 0x01])  # false syncs among them
    dec = p.Decoder(p.HOST_SYNC)
    out = dec.feed(noise + data[:10] + noise + data[10:])
    # The noise spliced into the first frame costs that frame (the spliced bytes break it).
    assert out[-(len(frames) - 1):] == frames[1:]
    assert dec.garbage_bytes >= len(noise) and dec.pending == 0


@pytest.mark.parametrize("position", range(10))
def test_a_corrupted_byte_loses_exactly_that_frame(position: int) -> None:
    good = p.encode_sample(5, (3, -4), True)
    bad = bytearray(good)
    bad[position] ^= 0x10
    dec = p.Decoder(p.HOST_SYNC)
    out = dec.feed(bytes(bad) + p.encode_reset(9))
    assert out == [p.Reset(9)]  # never a wrong sample: the CRC (or the header check) refuses it
    if position >= 3:  # a valid header: the CRC is what caught it
        assert dec.crc_errors == 1


def test_status_with_bad_crc_is_refused_and_counted() -> None:
    data = bytearray(p.encode_status(STATUS))
    data[-1] ^= 0xFF
    dec = p.Decoder(p.CARD_SYNC)
    assert dec.feed(bytes(data)) == [] and dec.crc_errors == 1
    assert dec.feed(p.encode_status(STATUS)) == [STATUS]
    with pytest.raises(p.ProtocolError):
        p.decode(bytes(data))


def test_decoder_waits_for_a_whole_frame() -> None:
    data = p.encode_status(STATUS)
    dec = p.Decoder(p.CARD_SYNC)
    assert dec.feed(data[:20]) == [] and dec.pending == 20
    assert dec.feed(data[20:]) == [STATUS] and dec.pending == 0


def test_three_axis_status_round_trips() -> None:
    s = p.Status(0, 0, 512, p.ST_DRIVE_FAULT, 2, 0x2310, 1, 0, (1, 2, -3), (4, -5, 6),
                 (0, 0, 0), (0, 1, -1))
    data = p.encode_status(s)
    assert len(data) == 3 + 14 + 3 * 12 + 2 + 2  # ..., the axes, the io word, the CRC
    assert p.decode(data) == s


def test_the_probe_input_has_a_bit_of_its_own_beside_three_axes_limits() -> None:
    every_limit = 0xFC  # bits 2-7: all six switches of X, Y and Z open
    s = p.Status(0, 0, 256, 0, 0, 0, 1, 1, (1, 2, 3), (3, 4, 5), (0, 0, 0), (0, 0, 0),
                 io=every_limit | p.IO_PROBE_INPUT)
    back = p.decode(p.encode_status(s))
    assert back.io & p.IO_PROBE_INPUT and back.io & 0xFC == every_limit


def test_limit_bits_name_each_axis_and_side() -> None:
    bits = {(axis, side): p.limit_bits(axis, side) for axis in range(3) for side in (-1, 1)}
    assert sorted(bits.values()) == [0x04, 0x08, 0x10, 0x20, 0x40, 0x80]  # bits 2-7, once each
    for (axis, side), bit in bits.items():
        assert p.limit_of(bit | p.IO_DISABLED | p.IO_ESTOP_INPUT, 3) == (axis, side)
    assert p.limit_of(p.IO_DISABLED | p.IO_ESTOP_INPUT, 3) is None


def test_outputs_frame_refuses_what_it_cannot_carry() -> None:
    with pytest.raises(p.ProtocolError):
        p.encode_outputs(1, 1 << 16, [0.0] * 4)
    with pytest.raises(p.ProtocolError):
        p.encode_outputs(1, 0, [0.0] * 3)
