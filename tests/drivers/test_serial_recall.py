"""RECALL on the serial card: queued samples taken back, all or none, by the card's own count.

The card's logic in-process for the cases that need an exact FIFO, and the host's SerialCard
against `cncctl simdrive serial` in its own process on a pty for the round trip."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from test_serial_card import STATUS_S, _card, peer

from controller.config import load_config
from drivers.base import CardStatus
from drivers.registry import make_drive
from drivers.serial import protocol as p


def _queue(card: Any, first_seq: int, n: int, end: bool = False) -> None:
    for i in range(n):
        card.handle(p.Sample(first_seq + i, (1, -1), end and i == n - 1))


def test_the_card_takes_back_the_newest_samples_and_expects_their_seq_again() -> None:
    card, sent = _card()
    _queue(card, 10, 50)
    card.handle(p.Recall(7, 40, 20))  # seq 40..59: 20 taken back, 30 stay
    assert sent[-1].reply_to == 7 and sent[-1].rx_seq == 39 and sent[-1].fifo_level == 30
    card.handle(p.Sample(40, (2, 2)))  # the seq taken back is the next one expected
    assert not card.latched & p.ST_SEQ_GAP and len(card.fifo) == 31


def test_the_card_refuses_what_would_leave_too_few_or_ends_the_stream() -> None:
    card, sent = _card()
    _queue(card, 0, 30)
    card.handle(p.Recall(1, 15, 20))  # 15 would stay, 20 asked for
    assert sent[-1].rx_seq == 29 and sent[-1].fifo_level == 30
    card.handle(p.Recall(2, 65000, 0))  # older than anything queued (wraps far back)
    assert sent[-1].rx_seq == 29 and sent[-1].fifo_level == 30
    _queue(card, 30, 5, end=True)
    card.handle(p.Recall(3, 33, 0))  # the stream's last sample among them
    assert sent[-1].rx_seq == 34 and sent[-1].fifo_level == 35
    card.handle(p.Sample(29, (0, 0)))  # nothing taken back: a repeat is a gap
    assert card.latched & p.ST_SEQ_GAP


def test_the_card_refuses_once_the_samples_have_executed() -> None:
    card, sent = _card()
    _queue(card, 0, 30)
    card.clock(25)
    card.handle(p.Recall(4, 20, 0))  # 20..24 executed already
    assert sent[-1].rx_seq == 29 and sent[-1].fifo_level == 5


def test_the_host_takes_back_frames_through_the_card_process() -> None:
    """240 frames queued (240 ms), the newest 120 taken back with 20 kept: the card has
    100 ms to answer before it would have to refuse. The stream then goes on with the
    frames sent in their place, and the step counters show which ran."""
    cfg = load_config("serial")
    with peer() as (port, _):
        drive = make_drive(cfg, port=port)
        with drive:
            drive.write_frames(np.tile([1, -1], (240, 1)))
            assert drive.recall_frames(120, 20) == 120
            assert drive.fifo_level() <= 120
            assert drive.recall_frames(200, 20) == 0  # fewer than 200 + 20 are queued
            drive.write_frames(np.tile([3, 0], (10, 1)), end_of_stream=True)
            assert drive.recall_frames(5, 0) == 0  # the stream's end among them
            _wait_idle(drive)
            assert drive.status() == CardStatus.OK
            cmd, _ = drive.position_counts()
            assert cmd.tolist() == [120 + 30, -120]


def _wait_idle(drive: Any, timeout_s: float = 3.0) -> None:
    deadline_s = time.monotonic() + timeout_s
    while drive.fifo_level() and time.monotonic() < deadline_s:
        time.sleep(STATUS_S / 2)
    assert drive.fifo_level() == 0
    time.sleep(2 * STATUS_S)  # one report after the last sample: the counters of its period
