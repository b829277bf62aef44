"""Homing on the serial card: the HOME frame, the card's sequence, reports and refusals.

The card is `cncctl simdrive serial`, in its own process on a pty."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from homing_helpers import homing_config, peer

from controller.config import MachineConfig, load_config
from drivers.base import CardStatus
from drivers.errors import DriveError, HomingError
from drivers.serial import protocol as p
from drivers.serial.backend import SerialCard
from drivers.serial.homing import request_for
from drivers.serial.sim_peer import PeerCard

HOME = p.Home(7, 0b01, (p.HomeAxis(-1, True, 20000, 2000, 500000, -149000, -145000, 330000),
                        p.HomeAxis()))


def counts(mm: list[float]) -> list[int]:
    return [round(v / 0.001) for v in mm]


@contextmanager
def opened(config: MachineConfig, port: str, **options: Any) -> Iterator[SerialCard]:
    card = SerialCard(config, port=port, link_timeout_s=0.1, **options)
    card.open()
    try:
        yield card
    finally:
        card.close()


def test_home_frame_transcript() -> None:
    data = p.encode(HOME)
    assert data[:6].hex() == "a51337070001"  # HOME, 55 bytes: token 7, mask X
    assert len(data) == 3 + 3 + 2 * 26 + 2 and p.decode(data) == HOME
    with pytest.raises(p.ProtocolError, match="out of range"):
        p.encode_home(1, 1, [p.HomeAxis(direction=-1, search_pps=-5), p.HomeAxis()])


def test_request_carries_the_config_in_pulses(tmp_path: Path) -> None:
    config, _ = homing_config("serial", tmp_path, use_index=True)
    mask, blocks, _ = request_for(SerialCard(config, port="/dev/null"), (0, 1))
    assert mask == 0b11
    assert blocks[0] == p.HomeAxis(-1, True, 20000, 2000, 500000, -149000, -145000, 330000)
    assert blocks[1].direction == 1 and blocks[1].final_pulses == 145000


def test_the_card_refuses_home_while_samples_are_queued() -> None:
    sent: list[bytes] = []
    card = PeerCard(load_config("serial"), {}, sent.append)
    card.handle_bytes(p.encode_sample(0, (1, 1)))  # a stream under way
    card.handle_bytes(p.encode(HOME))
    reply = p.decode(sent[-1])
    assert isinstance(reply, p.Status) and reply.reply_to == 7
    assert reply.latched & p.ST_HOME_FAILED and reply.fault_code == p.HOME_BUSY
    assert not reply.latched & p.ST_HOMING and not reply.latched & p.ST_LATCHED
    card.handle_bytes(p.encode_reset(8))
    assert not p.decode(sent[-1]).latched & p.ST_HOME_FAILED
    card.handle_bytes(p.encode(HOME))  # idle now: accepted, running
    assert p.decode(sent[-1]).latched & p.ST_HOMING


def test_homing_through_the_pty(tmp_path: Path) -> None:
    config, _ = homing_config("serial", tmp_path)
    with peer("serial", None, "true_start_mm=[-140.0, 140.0]", "start_mm=[3.0, -2.0]") \
            as (_, port), opened(config, port) as card:
        assert card.homed() == (False, False)
        assert card.position_counts()[0].tolist() == counts([3.0, -2.0])
        t0 = time.monotonic()
        card.home([0, 1], timeout_s=10.0)
        assert time.monotonic() - t0 < 5.0
        cmd, enc = card.position_counts()
        assert cmd.tolist() == counts([-145.0, 145.0]) and enc.tolist() == cmd.tolist()
        # Settled, not swinging through the final point: the servo rings after the final move,
        # and a homing done at the first pass within half a count read a count off 10-20 ms
        # later. Every status of the next 0.1 s (one each 10 ms) reads the same.
        deadline = time.monotonic() + 0.1
        while time.monotonic() < deadline:
            cmd, enc = card.position_counts()
            assert enc.tolist() == cmd.tolist() == counts([-145.0, 145.0])
            time.sleep(0.002)
        assert card.homed() == (True, True) and card.status() == CardStatus.OK
        card.write_frames(np.tile([5, -5], (100, 1)).astype(np.int64), end_of_stream=True)
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline and card.position_counts()[0][0] != -144500:
            time.sleep(0.02)
        assert card.position_counts()[0].tolist() == counts([-144.5, 144.5])
        assert card.status() == CardStatus.OK
        with pytest.raises(HomingError, match="no homing sequence|no axis 5"):
            card.home([5])


def test_a_card_without_a_switch_says_not_found(tmp_path: Path) -> None:
    config, _ = homing_config("serial", tmp_path, travel_mm=[-20.0, 20.0])
    with peer("serial", None, "home_switch_mm=[-19.0, null]") as (_, port), \
            opened(config, port) as card:
        with pytest.raises(HomingError, match=r"Y axis homing failed: home switch not found "
                                              r"within 44\.0 mm") as err:
            card.home([0, 1], timeout_s=10.0)
        assert err.value.axis == "y" and card.homed() == (False, False)
        assert card.status() == CardStatus.OK  # a failed homing does not halt the card
        card.home([0])
        assert card.homed() == (True, False)


def test_drive_fault_during_homing_and_time_out(tmp_path: Path) -> None:
    config, _ = homing_config("serial", tmp_path)
    with peer("serial", None, "true_start_mm=[-100.0, 100.0]", "homing_fault_after_s=0.2",
              "drive_fault_axis=1") as (_, port), opened(config, port) as card:
        with pytest.raises(HomingError, match="Y axis homing failed: drive fault during "
                                              "homing: Y axis drive fault 0x2310"):
            card.home([0, 1], timeout_s=10.0)
        assert CardStatus.FAULT in card.status()
        with pytest.raises(HomingError, match="halted"):
            card.home([0])
        card.reset()
        with pytest.raises(HomingError, match=r"time-out: not homed within 0\.2 s"):
            card.home([0], timeout_s=0.2)
        assert card.homed() == (False, False) and card.status() == CardStatus.OK
        card.write_frames(np.ones((5, 2), dtype=np.int64))
        with pytest.raises(HomingError, match="frames are streaming"):
            card.home([0])


def test_peer_options_are_checked() -> None:
    with pytest.raises(DriveError, match="home_switch_mm' must be a list of 2"):
        PeerCard(load_config("serial"), {"home_switch_mm": [1.0]}, lambda _: None)
