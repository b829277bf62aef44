"""The serial card's take-back, host side: one RECALL request; its reply says what was done."""

from __future__ import annotations

from typing import Any

from drivers.errors import LostCommunicationError
from drivers.serial import protocol as p

# drivers.serial.backend.SerialCard, whose link internals this uses (not imported: the backend
# imports this module; see drivers/serial/homing.py).
SerialCard = Any


def recall(card: SerialCard, n: int, keep: int) -> int:
    """RECALL: the card takes back the last n samples if `keep` stay queued before them (it
    checks against what it has clocked by then); its reply's rx_seq says whether it did.
    No reply: the link is lost (the next feedback() raises), nothing taken back."""
    card._check_link()
    first_seq = card._base + card._written - n
    try:
        reply = card._request(lambda token: p.encode_recall(token, first_seq, keep), "recall")
    except LostCommunicationError as exc:
        card._mark_lost(str(exc))
        return 0
    with card._cond:
        if card._unwrap(reply.rx_seq) != card._written - n - 1:
            return 0
        card._written -= n
        card._rx_idx = card._written - 1
        return n
