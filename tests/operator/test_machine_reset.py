"""cncd's reset after a lost drive link opens the drive again instead of failing until restart."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from controller.config import load_config
from controller.operator.daemon.log import EventLog
from controller.operator.daemon.machine import Machine, State
from drivers.base import CardStatus
from drivers.errors import LostCommunicationError
from drivers.sim.card import SimCard


def test_reset_after_a_lost_link_reopens_the_drive(tmp_path: Path) -> None:
    config = load_config("xy_table")
    card = SimCard(config, realtime=False)
    card.open()
    try:
        machine = Machine(config, card, tmp_path, EventLog(100), lambda topic, event: None)
        machine.reset()
        assert machine.state is State.IDLE
        card.inject_lost_comm()  # the link dies (the job, had one run, would have faulted)
        machine.reset()  # was: "drive reset failed: lost communication" until a restart
        assert machine.state is State.IDLE
        card.feedback()  # the link answers again
        assert "opening it again" in " ".join(e["message"] for e in machine.log.last(10))
    finally:
        card.close()


def test_reset_after_a_lost_canopen_adapter_says_why_until_it_is_back(tmp_path: Path) -> None:
    """The adapter (a simulated slcan USB-CAN stick behind a udev-style symlink) is pulled:
    each reset names the missing adapter (was: a ValueError from python-can's slcan reader,
    then "drive is not open" until a restart); plugged in again, reset opens it."""
    import uuid

    import pytest

    from controller.operator.daemon.protocol import ProtocolError
    from drivers.canopen.backend import CanopenDrive
    from drivers.canopen.sim_drive import SimDriveSet
    from drivers.canopen.slcan_pty import SlcanPty

    config = load_config("canopen")
    link = tmp_path / "can0"

    def plug() -> tuple[SimDriveSet, SlcanPty]:
        channel = f"t-{uuid.uuid4().hex[:8]}"
        drives, adapter = SimDriveSet(config, {}, channel=channel), SlcanPty(channel)
        adapter.start()
        link.unlink(missing_ok=True)
        link.symlink_to(adapter.path)
        return drives, adapter

    drives, adapter = plug()
    drive = CanopenDrive(config, realtime=True, **(dict(config.drive.options) | {
        "channel": str(link), "sdo_timeout_s": 0.2}))
    drive.open()
    try:
        machine = Machine(config, drive, tmp_path, EventLog(100), lambda topic, event: None)
        machine.reset()
        assert machine.state is State.IDLE
        adapter.close()  # pulled: the heartbeats stop, the link is lost
        drives.close()
        link.unlink()
        deadline_s = time.monotonic() + 5
        while CardStatus.LOST_COMM not in _status(drive):
            assert time.monotonic() < deadline_s
            time.sleep(0.05)
        for _ in range(2):
            with pytest.raises(ProtocolError, match=f"no CAN adapter at {link}"):
                machine.reset()
        drives, adapter = plug()
        machine.reset()
        assert machine.state is State.IDLE and drive.is_open
        assert drive.drive_states() == ["OPERATION ENABLED"] * 2
    finally:
        drive.close()
        adapter.close()
        drives.close()


def _status(drive: Any) -> CardStatus:
    try:
        return drive.status()
    except LostCommunicationError:
        return CardStatus.LOST_COMM
