"""Homing on CiA 402 drives (mode 6) over the wire protocol, against the simulated drives.

`cncctl simdrive canopen` in its own process behind the fake slcan adapter; the corner cases
in-process on python-can `virtual`."""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from daemon_helpers import LOADED_CANOPEN
from homing_helpers import homing_config, peer

from controller.config import MachineConfig
from drivers.base import CardStatus
from drivers.canopen import bringup
from drivers.canopen import cia402 as c
from drivers.canopen.backend import CanopenDrive
from drivers.canopen.sim_drive import SimDriveSet
from drivers.errors import DriveError, HomingError


def counts(mm: list[float]) -> list[int]:
    return [round(v / 0.001) for v in mm]


@contextmanager
def opened(config: MachineConfig, **options: Any) -> Iterator[CanopenDrive]:
    # the subject is homing: a loaded machine's link timeouts (tests/daemon_helpers.py)
    drive = CanopenDrive(config, realtime=True,
                         **(dict(config.drive.options) | LOADED_CANOPEN | options))
    drive.open()
    try:
        yield drive
    finally:
        drive.close()


def sdo(drive: CanopenDrive, axis: int, index: int, subindex: int | None = None) -> int:
    return bringup.sdo_read(drive._nodes[axis], drive.axes[axis], index, subindex)


# -- through the wire, the drives in their own process -----------------------------------
def test_homing_through_the_slcan_pty(tmp_path: Path) -> None:
    config, path = homing_config("canopen", tmp_path)
    with peer("canopen", path, "true_start_mm=[-140.0, 140.0]") as (_, dev), \
            opened(config, channel=dev) as drive:
        assert drive.homed() == (False, False)
        assert drive.position_counts()[0].tolist() == [0, 0]  # what the drives say at power-up
        t0 = time.monotonic()
        drive.home([0, 1], timeout_s=10.0)
        assert time.monotonic() - t0 < 5.0
        cmd, enc = drive.position_counts()
        assert cmd.tolist() == counts([-145.0, 145.0]) and enc.tolist() == cmd.tolist()
        assert drive.homed() == (True, True)
        # The drives are back in CSP, enabled; the methods and offsets went out as documented.
        assert [sdo(drive, i, c.MODE_DISPLAY) for i in (0, 1)] == [c.MODE_CSP] * 2
        assert [sdo(drive, i, c.HOMING_METHOD) for i in (0, 1)] == [17, 18]
        assert [sdo(drive, i, c.HOME_OFFSET) for i in (0, 1)] == [-149000, 149000]
        assert [sdo(drive, i, c.HOMING_SPEEDS, 1) for i in (0, 1)] == [20000, 20000]
        assert drive.drive_states() == ["OPERATION ENABLED"] * 2
        # A stream then starts from there, numbered from 0 (homing used no stream index).
        drive.write_frames(np.tile([5, -5], (100, 1)).astype(np.int64), end_of_stream=True)
        deadline = time.monotonic() + 3.0
        rows = []
        while time.monotonic() < deadline and sum(len(f) for f in rows) < 100:
            rows.append(drive.feedback())
            time.sleep(0.02)
        assert np.concatenate([f.seq for f in rows]).tolist() == list(range(100))
        assert drive.position_counts()[0].tolist() == counts([-144.5, 144.5])
        assert drive.status() == CardStatus.OK


def test_a_drive_without_a_switch_reports_a_homing_error(tmp_path: Path) -> None:
    config, path = homing_config("canopen", tmp_path, travel_mm=[-20.0, 20.0])
    with peer("canopen", path, "home_switch_mm=[-19.0, null]") as (_, dev), \
            opened(config, channel=dev) as drive:
        with pytest.raises(HomingError, match=r"Y axis homing failed: the drive reports a "
                                              r"homing error \(0x6041 = 0x.*bit 13\)") as err:
            drive.home([0, 1], timeout_s=10.0)
        assert err.value.axis == "y"
        assert drive.homed() == (False, False)
        assert [sdo(drive, i, c.MODE_DISPLAY) for i in (0, 1)] == [c.MODE_CSP] * 2
        assert drive.status() == CardStatus.OK
        drive.home([0], timeout_s=10.0)  # X has its switch
        assert drive.homed() == (True, False)
        assert drive.position_counts()[0][0] == counts([-15.0])[0]


def test_a_drive_fault_during_homing_is_a_homing_error(tmp_path: Path) -> None:
    config, path = homing_config("canopen", tmp_path)
    with peer("canopen", path, "true_start_mm=[-100.0, 100.0]",
              "drive_fault_after_s=0.3") as (_, dev), opened(config, channel=dev) as drive:
        with pytest.raises(HomingError, match="X axis homing failed: drive fault during "
                                              "homing: X axis drive .*EMCY 0x2310"):
            drive.home([0, 1], timeout_s=10.0)
        assert CardStatus.FAULT in drive.status() and drive.homed() == (False, False)
        drive.reset()  # fault reset, re-enabled in CSP where they stand
        assert drive.status() == CardStatus.OK
        assert drive.drive_states() == ["OPERATION ENABLED"] * 2


# -- in-process, on a virtual bus ---------------------------------------------------------
@contextmanager
def bus(config: MachineConfig, sim_options: dict[str, Any],
        **drive_options: Any) -> Iterator[tuple[SimDriveSet, CanopenDrive]]:
    channel = f"t-{uuid.uuid4().hex[:8]}"
    sims = SimDriveSet(config, sim_options, channel=channel)
    try:
        with opened(config, interface="virtual", channel=channel, sdo_timeout_s=0.1,
                    **drive_options) as drive:
            yield sims, drive
    finally:
        sims.close()


def test_index_methods_land_on_the_mark_past_the_release(tmp_path: Path) -> None:
    config, _ = homing_config("canopen", tmp_path, use_index=True)
    with bus(config, {"true_start_mm": [-140.0, 140.0], "home_switch_mm": [-148.6, 148.6],
                      "index_pitch_mm": 0.5}) as (sims, drive):
        drive.home([0, 1], timeout_s=10.0)
        assert [sdo(drive, i, c.HOMING_METHOD) for i in (0, 1)] == [1, 2]
        assert drive.position_counts()[0].tolist() == counts([-145.0, 145.0])
        # Methods 1/2 leave the switch (toward +/-) and take the first index pulse after the
        # release edge -148.6 / 148.6: -148.5 and 148.5 read home_mm (-149, 149).
        found = np.array([a.actual_mm for a in sims.axes]) + sims.switches.offset_mm \
            - drive.position_counts()[1] * 0.001 + np.array([-149.0, 149.0])
        assert np.allclose(found, [-148.5, 148.5], atol=2e-3)


def test_the_host_stops_a_drive_that_searches_too_far(tmp_path: Path) -> None:
    config, _ = homing_config("canopen", tmp_path, travel_mm=[-20.0, 20.0])
    with bus(config, {"home_switch_mm": [None, 19.0], "search_limit_mm": 1000.0}) \
            as (sims, drive):
        with pytest.raises(HomingError, match=r"X axis homing failed: home switch not found "
                                              r"within 49\.0 mm .*halted"):
            drive.home([0, 1], timeout_s=10.0)
        assert drive.homed() == (False, False) and drive.status() == CardStatus.OK
        x = drive.position_counts()[0][0]
        time.sleep(0.1)
        assert drive.position_counts()[0][0] == x  # halted, and CSP holds it there


def test_refusals_stream_time_out_and_no_homing_mode(tmp_path: Path) -> None:
    config, _ = homing_config("canopen", tmp_path)
    with bus(config, {"true_start_mm": [-100.0, 100.0]}) as (sims, drive):
        drive.write_frames(np.ones((50, 2), dtype=np.int64))
        with pytest.raises(HomingError, match="frames are streaming"):
            drive.home([0])
        drive.write_frames(np.zeros((0, 2), dtype=np.int64), end_of_stream=True)
        time.sleep(0.1)
        with pytest.raises(HomingError, match=r"X axis homing failed: time-out: not homed "
                                              r"within 0\.2 s \(halted\)"):
            drive.home([0], timeout_s=0.2)
        assert drive.status() == CardStatus.OK and drive.homed() == (False, False)
        sims.axes[1].node.data_store[c.SUPPORTED_MODES] = {0: (0x80).to_bytes(4, "little")}
        with pytest.raises(HomingError, match=r"Y axis homing failed: .*has no homing mode "
                                              r"\(0x6502 = 0x00000080"):
            drive.home([1])


def test_home_offset_sign_option_is_checked(tmp_path: Path) -> None:
    config, _ = homing_config("canopen", tmp_path)
    with pytest.raises(DriveError, match="home_offset_sign: must be 1 or -1"):
        CanopenDrive(config, home_offset_sign=0)
    assert CanopenDrive(config, home_offset_sign=-1).o.home_offset_sign == -1
