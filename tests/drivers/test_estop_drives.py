"""Drive.disable() and the e-stop input on every backend's peer: the CiA 402 drives on a
virtual bus, the serial card in its own process, and the serial protocol's new frame and byte."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from test_canopen_sim import bus, ramp, wait_for
from test_serial_card import peer

from controller.config import load_config
from drivers.errors import DriveError
from drivers.registry import make_drive
from drivers.serial import protocol as p


def test_the_disable_frame_and_the_io_byte_round_trip() -> None:
    assert p.decode(p.encode_disable(7)) == p.Disable(7)
    status = p.Status(0, 0, 256, 0, 0, 0, 1, 1, (1, 2), (3, 4), (0, 0), (0, 0),
                      io=p.IO_DISABLED | p.IO_ESTOP_INPUT)
    assert p.decode(p.encode_status(status)) == status


def test_canopen_disable_is_quick_stop_then_disable_voltage_until_reset(tmp_path: Path) -> None:
    trip = tmp_path / "estop"
    with bus({"estop_input_file": str(trip)}) as (sims, drive):
        assert not drive.estop_input()
        drive.write_frames(ramp(100), end_of_stream=True)
        wait_for(lambda: drive.fifo_level() == 0)
        trip.touch()
        wait_for(drive.estop_input)  # statusword bit 14, in every TPDO1
        drive.disable()
        assert [a.state for a in sims.axes] == ["SWITCH ON DISABLED"] * 2
        assert drive.disabled and not drive.status().halted  # asked for: no fault latched
        with pytest.raises(DriveError, match="disabled"):
            drive.write_frames(ramp(1))
        with pytest.raises(DriveError, match="e-stop input is tripped"):
            drive.reset()
        trip.unlink()
        wait_for(lambda: not drive.estop_input())
        drive.reset()
        assert drive.drive_states() == ["OPERATION ENABLED"] * 2 and not drive.disabled
        start = drive.position_counts()[0]
        drive.feedback()
        drive.write_frames(ramp(20), end_of_stream=True)
        wait_for(lambda: drive.fifo_level() == 0)
        assert (drive.position_counts()[0] - start).tolist() == [20 * 58, -20 * 58]


def _io(drive: object) -> int:
    drive._request(p.encode_status_request, "status request")  # type: ignore[attr-defined]
    return drive._last.io  # type: ignore[attr-defined]


def test_the_serial_card_disables_on_its_frame_and_reports_its_input(tmp_path: Path) -> None:
    trip = tmp_path / "estop"
    with peer(f"estop_input_file={trip}") as (port, _):
        drive = make_drive(load_config("serial"), port=port, realtime=True)
        with drive:
            assert _io(drive) == 0 and not drive.estop_input()
            drive.disable()
            assert _io(drive) & p.IO_DISABLED and drive.disabled
            trip.touch()
            deadline_s = time.monotonic() + 2.0
            while not drive.estop_input():
                assert time.monotonic() < deadline_s
                time.sleep(0.005)
            assert _io(drive) & p.IO_ESTOP_INPUT
            with pytest.raises(DriveError, match="e-stop input is tripped"):
                drive.reset()
            trip.unlink()
            while drive.estop_input():
                assert time.monotonic() < deadline_s + 2.0
                time.sleep(0.005)
            drive.reset()
            assert _io(drive) == 0 and not drive.disabled
            start = drive.position_counts()[0]
            drive.write_frames(np.tile([5, -5], (20, 1)), end_of_stream=True)
            while not np.array_equal(drive.position_counts()[0] - start, [100, -100]):
                assert time.monotonic() < deadline_s + 4.0
                time.sleep(0.005)
