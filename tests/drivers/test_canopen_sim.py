"""The canopen backend against the simulated CiA 402 drives, in-process on python-can `virtual`."""

from __future__ import annotations

import re
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

from controller.config import load_config
from controller.servo.model import discretise
from drivers.base import CardStatus
from drivers.canopen import cia402 as c
from drivers.canopen.backend import CanopenDrive
from drivers.canopen.sim_drive import SimAxis402, SimDriveSet
from drivers.errors import DriveError, DriveFaultError, LostCommunicationError, UnderrunError
from drivers.registry import make_drive

CONFIG = load_config("canopen")
T_S = CONFIG.sample_period_s


def wait_for(cond: Callable[[], Any], timeout_s: float = 2.0) -> Any:
    """Poll an event (not a fixed sleep); fail with the time it took. What reaches the
    simulated drives through the bus's notifier thread is waited for with the default: on a
    loaded machine it is late by what the scheduler gives, which the code does not bound (the
    reaction times it does bound are asserted where they are measured)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = cond()
        if value:
            return value
        time.sleep(0.002)
    raise AssertionError(f"condition not met within {timeout_s} s")


@contextmanager
def bus(sim_options: dict[str, Any] | None = None, open_drive: bool = True,
        **drive_options: Any) -> Iterator[tuple[SimDriveSet, CanopenDrive]]:
    channel = f"t-{uuid.uuid4().hex[:8]}"
    sims = SimDriveSet(CONFIG, sim_options or {}, channel=channel)
    options = dict(CONFIG.drive.options) | {"interface": "virtual", "channel": channel,
                                            "sdo_timeout_s": 0.1} | drive_options
    drive = CanopenDrive(CONFIG, realtime=True, **options)
    try:
        if open_drive:
            drive.open()
        yield sims, drive
    finally:
        drive.close()
        sims.close()


def ramp(n: int, per_frame: int = 58) -> np.ndarray:
    return np.tile([per_frame, -per_frame], (n, 1)).astype(np.int64)


# -- options ------------------------------------------------------------------------------
def test_options_are_strict_and_virtual_time_is_refused() -> None:
    with pytest.raises(DriveError, match="unknown canopen option.*bogus"):
        CanopenDrive(CONFIG, bogus=1)
    with pytest.raises(DriveError, match="virtual time"):
        make_drive(CONFIG, realtime=False)
    with pytest.raises(DriveError, match="node_ids: expected a list of 2"):
        CanopenDrive(CONFIG, node_ids=[1])
    with pytest.raises(DriveError, match="unknown simulated drive option.*nope"):
        SimDriveSet(CONFIG, {"nope": 1}, channel="t-strict")
    assert type(make_drive(CONFIG, realtime=True)).__name__ == "CanopenDrive"


# -- the simulated drive on its own (direct calls: deterministic) -------------------------
@pytest.fixture
def sim() -> Iterator[SimDriveSet]:
    sims = SimDriveSet(CONFIG, {"lag_mm": 2.0, "lag_after_s": 0.1, "fault_axis": "y"},
                       channel=f"t-{uuid.uuid4().hex[:8]}", watchdog=False)
    for axis in sims.axes:
        axis.node.nmt.state = "OPERATIONAL"
        axis.mode = c.MODE_CSP
    yield sims
    sims.close()


def test_state_machine_transitions_and_fault_reset_edge(sim: SimDriveSet) -> None:
    a = sim.axis("x")
    walk = [(c.CW_SHUTDOWN, "READY TO SWITCH ON"), (c.CW_SWITCH_ON, "SWITCHED ON"),
            (c.CW_ENABLE_OPERATION, "OPERATION ENABLED"), (c.CW_QUICK_STOP, "QUICK STOP ACTIVE"),
            (c.CW_ENABLE_OPERATION, "OPERATION ENABLED"), (c.CW_SHUTDOWN, "READY TO SWITCH ON"),
            (c.CW_ENABLE_OPERATION, "OPERATION ENABLED"), (c.CW_DISABLE_VOLTAGE,
                                                           "SWITCH ON DISABLED")]
    for cw, state in walk:
        a.command(cw)
        assert c.state_of(a.statusword) == state, (hex(cw), state)
    a.fault(0x2310)
    assert c.state_of(a.statusword) == "FAULT" and a.error_code == 0x2310
    a.command(c.CW_ENABLE_OPERATION)  # ignored in FAULT
    a.command(c.CW_FAULT_RESET)  # rising edge of bit 7: transition 15
    assert c.state_of(a.statusword) == "SWITCH ON DISABLED" and a.error_code == 0
    a.fault(0x2310)
    a.command(c.CW_FAULT_RESET)  # bit 7 still high: no edge, stays in FAULT
    assert c.state_of(a.statusword) == "FAULT"


def enable(a: SimAxis402) -> None:
    for cw in (c.CW_SHUTDOWN, c.CW_SWITCH_ON, c.CW_ENABLE_OPERATION):
        a.command(cw)


def test_csp_follows_the_target_through_the_servo_model(sim: SimDriveSet) -> None:
    """58 counts/ms = 58 mm/s: steady lag V (a1 - b1) / a0 as the sim card; exact at rest."""
    a = sim.axis("x")
    enable(a)
    target = 0
    for _ in range(60):  # 60 ms, before the y axis's injected lag starts at 0.1 s
        target += 58
        a.latched = (c.CW_ENABLE_OPERATION, target)
        sim.on_sync()
    lag_counts = a.ref - a.position
    expected = 58.0 * discretise(CONFIG.axes[0].servo, T_S).steady_lag_s * 1e3
    assert abs(lag_counts - expected) <= 1.0
    assert a.statusword & c.SW_FOLLOWS_COMMAND
    for _ in range(300):
        sim.on_sync()
    assert a.position == target == a.ref


def test_following_error_window_faults_with_emcy_8611(sim: SimDriveSet) -> None:
    y = sim.axis("y")
    y.window, y.timeout_ms = 1000, 10  # 1 mm, 10 ms
    enable(y)
    syncs = 0
    while y.state != "FAULT" and syncs < 400:
        sim.on_sync()
        syncs += 1
    # lag starts at 0.1 s, ramps 0.1 mm per cycle past 1 mm in 10 cycles, then 10 ms more
    assert y.state == "FAULT" and y.error_code == c.EMCY_FOLLOWING_ERROR
    assert y.emcy_sent == [c.EMCY_FOLLOWING_ERROR] and 115 <= syncs <= 125


def test_master_heartbeat_consumer_faults_with_emcy_8130(sim: SimDriveSet) -> None:
    for a in sim.axes:
        a.consumer_id, a.consumer_ms = sim.master_id, 300
        enable(a)
    sim.check_master(now_s=5.0)  # never seen a heartbeat: the consumer is not armed
    assert all(a.state == "OPERATION ENABLED" for a in sim.axes)
    sim.master_seen_s = 1.0
    sim.check_master(now_s=1.29)
    assert all(a.state == "OPERATION ENABLED" for a in sim.axes)
    sim.check_master(now_s=1.31)
    assert [(a.state, a.error_code) for a in sim.axes] == [("FAULT", 0x8130)] * 2


def test_a_starved_simulator_does_not_invent_a_lost_master_heartbeat(sim: SimDriveSet) -> None:
    """The master's frames wait unread, or the look itself comes late: the simulated drive is
    behind, the master is not silent (under load the peer faulted both drives with 0x8130)."""
    for a in sim.axes:
        a.consumer_id, a.consumer_ms = sim.master_id, 300
        enable(a)
    sim.master_seen_s, sim._last_watch_s = 1.0, 1.0
    sim.watch(1.5)  # woke 0.5 s late: the sleep is not the master's silence
    assert all(a.state == "OPERATION ENABLED" for a in sim.axes)
    sim.host_pending = lambda: True
    for now_s in (1.51, 1.52, 1.9):
        sim._last_watch_s = now_s - 0.01
        sim.watch(now_s)
    assert all(a.state == "OPERATION ENABLED" for a in sim.axes)
    sim.host_pending = lambda: False
    sim._last_watch_s = 1.9
    sim.watch(1.91)
    assert [(a.state, a.error_code) for a in sim.axes] == [("FAULT", 0x8130)] * 2


# -- backend + simulated drives (threads on the virtual bus) ------------------------------
def test_bringup_writes_the_objects_and_close_leaves_drives_disabled() -> None:
    with bus() as (sims, drive):
        assert drive.drive_states() == ["OPERATION ENABLED"] * 2
        for a in sims.axes:
            assert (a.window, a.timeout_ms, a.abort_option) == (1000, 10, 1)
            assert (a.consumer_id, a.consumer_ms) == (127, 300)
            assert a.mode == c.MODE_CSP and a.node.nmt._heartbeat_time_ms == 50
            assert a.node.sdo[c.INTERPOLATION_PERIOD][1].raw == 1
        drive.close()  # controlwords reach the simulated drives through the notifier thread
        wait_for(lambda: [a.state for a in sims.axes] == ["READY TO SWITCH ON"] * 2)
        assert [a.consumer_ms for a in sims.axes] == [0, 0]  # closing is not losing us


def test_streams_frames_and_settles_exactly() -> None:
    with bus() as (sims, drive):
        drive.write_frames(ramp(250), end_of_stream=True)
        wait_for(lambda: drive.fifo_level() == 0)
        wait_for(lambda: np.array_equal(*drive.position_counts()))
        cmd, enc = drive.position_counts()
        assert cmd.tolist() == [250 * 58, -250 * 58] == enc.tolist()
        assert [a.position for a in sims.axes] == [250 * 58, -250 * 58]
        fb = drive.feedback()
        # rows may be sparse or late (a TPDO1 64 cycles late is dropped), never wrong
        assert len(fb) >= 240 and np.all(np.diff(fb.seq) > 0)
        assert np.array_equal(fb.commanded_counts[:, 0], (fb.seq + 1) * 58)
        lag = fb.commanded_counts[:, 0] - fb.encoder_counts[:, 0]
        assert lag.min() >= 0 and lag[fb.seq > 100].max() <= 25  # the servo lag, 18.6 um
        assert drive.status() == CardStatus.OK  # an empty FIFO after end-of-stream is idle
        stats = drive.link_stats()
        assert stats["tpdos"] >= 500 and stats["rtt_p50_ms"] < 1.0


def test_underrun_mid_program_latches_and_quick_stops() -> None:
    with bus() as (sims, drive):
        drive.write_frames(ramp(30))  # no end-of-stream: the program continues
        wait_for(lambda: drive.status().halted, 1.0)
        assert drive.status() == CardStatus.UNDERRUN
        assert "underrun" in drive.fault_message()
        wait_for(lambda: [a.state for a in sims.axes] == ["QUICK STOP ACTIVE"] * 2)
        with pytest.raises(UnderrunError):
            drive.write_frames(ramp(1))


def test_following_error_emcy_latches_and_quick_stops_the_other_axis() -> None:
    with bus({"lag_mm": 2.0, "lag_after_s": 0.05, "fault_axis": "y"}) as (sims, drive):
        drive.write_frames(ramp(250))
        t0 = time.monotonic()
        wait_for(lambda: drive.status().halted, 1.0)
        assert time.monotonic() - t0 < 0.15  # 50 ms + 10-cycle ramp + 10 ms window time-out
        wait_for(lambda: "0x8611" in drive.fault_message(), 0.2)
        assert CardStatus.FOLLOWING_ERROR in drive.status()
        assert "Y axis drive (node 2) EMCY 0x8611 following error" in drive.fault_message()
        wait_for(lambda: [a.state for a in sims.axes] == ["QUICK STOP ACTIVE", "FAULT"])
        with pytest.raises(DriveFaultError, match="0x8611"):
            drive.write_frames(ramp(1))


def test_drive_fault_then_reset_re_enables_bumpless() -> None:
    with bus({"drive_fault_after_s": 0.05, "drive_fault_code": 0x2310}) as (sims, drive):
        drive.write_frames(ramp(200))
        wait_for(lambda: "0x2310" in drive.fault_message(), 1.0)
        assert "X axis drive (node 1) EMCY 0x2310 over-current" in drive.fault_message()
        assert CardStatus.FAULT in drive.status()
        wait_for(lambda: sims.axis("y").state == "QUICK STOP ACTIVE")
        # both axes at rest (the faulted one may have missed the last targets: cmd != enc)
        wait_for(lambda: all(abs(a.actual_mm * 1e3 - a.ref) < 0.5 for a in sims.axes))
        wait_for(lambda: drive.position_counts()[1].tolist() == [a.position for a in sims.axes])
        held = drive.position_counts()[1]
        drive.reset()
        assert drive.status() == CardStatus.OK and drive.fault_message() == ""
        assert drive.drive_states() == ["OPERATION ENABLED"] * 2
        wait_for(lambda: np.array_equal(*drive.position_counts()))
        start_cmd = drive.position_counts()[0]
        assert np.abs(start_cmd - held).max() <= 5  # target = actual: no jump (5 um settling)
        drive.feedback()
        drive.write_frames(ramp(50), end_of_stream=True)
        wait_for(lambda: drive.fifo_level() == 0)
        wait_for(lambda: np.array_equal(*drive.position_counts()))
        assert (drive.position_counts()[0] - start_cmd).tolist() == [50 * 58, -50 * 58]
        assert drive.status() == CardStatus.OK


def test_silent_drive_is_lost_communication_naming_it() -> None:
    with bus({"silent_after_s": 0.05}) as (sims, drive):
        drive.write_frames(ramp(250))
        t0 = time.monotonic()

        def lost() -> bool:
            try:
                drive.feedback()
            except LostCommunicationError:
                return True
            return False
        wait_for(lost, 1.0)
        assert time.monotonic() - t0 < 0.5  # 50 ms + 100 SYNC cycles without TPDO1 (+ load)
        with pytest.raises(LostCommunicationError, match=r"lost X axis drive \(node 1\)"):
            drive.status()
        # The quick stop and the disable reach the simulated drive through the bus's notifier
        # thread and the peer's own: waited for as events (the suite's four workers on two
        # loaded cores once took longer than 0.5 s), not timed.
        wait_for(lambda: sims.axis("y").state == "QUICK STOP ACTIVE")
        drive.close()
        wait_for(lambda: sims.axis("y").state == "SWITCH ON DISABLED")


def test_master_heartbeat_loss_faults_the_drives() -> None:
    with bus() as (sims, drive):
        drive._link.stop()  # the master hangs: no SYNC, no heartbeat
        t0 = time.monotonic()
        wait_for(lambda: all(a.state == "FAULT" for a in sims.axes), 1.0)
        assert 0.25 < time.monotonic() - t0 < 0.5  # the 300 ms consumer time
        assert [a.error_code for a in sims.axes] == [c.EMCY_HEARTBEAT] * 2


def test_sdo_abort_during_bringup_names_the_object_and_enables_nothing() -> None:
    with bus({"sdo_abort_index": 0x6065}, open_drive=False) as (sims, drive):
        with pytest.raises(DriveError, match=r"node 1\): SDO write of 0x6065 .* aborted"):
            drive.open()
        assert [a.state for a in sims.axes] == ["SWITCH ON DISABLED"] * 2


def test_probe_reads_identity_and_enables_nothing() -> None:
    with bus(open_drive=False) as (sims, drive):
        drive.probe()
        assert [a.state for a in sims.axes] == ["SWITCH ON DISABLED"] * 2
        assert [a.node.nmt.state for a in sims.axes] == ["PRE-OPERATIONAL"] * 2
    missing = CanopenDrive(CONFIG, interface="virtual", channel="t-nobody", sdo_timeout_s=0.05)
    with pytest.raises(DriveError, match=r"X axis drive \(node 1\) does not answer.*0x1000"):
        missing.probe()


@pytest.mark.parametrize(("inject", "flag", "text"), [
    ("statusword", CardStatus.FAULT, r"X axis drive \(node 1\) in FAULT \(statusword 0x02"),
    ("boot-up", CardStatus.FAULT, r"X axis drive \(node 1\) rebooted \(boot-up message\)"),
    ("short TPDO", CardStatus.BAD_FRAME, r"X axis drive \(node 1\): TPDO1 has 4 bytes"),
])
def test_unexpected_drive_messages_latch(inject: str, flag: CardStatus, text: str) -> None:
    with bus() as (sims, drive):
        x = sims.axis("x")
        if inject == "statusword":  # a fault without EMCY (a drive that sends none)
            with x.lock:
                x.state = "FAULT"
        elif inject == "boot-up":
            sims.network.send_message(0x700 + x.id, b"\x00")
        else:
            sims.network.send_message(x.tpdo_cob, b"\x27\x02\x00\x00")
        wait_for(lambda: drive.status().halted, 1.0)
        assert flag in drive.status()
        assert re.search(text, drive.fault_message()), drive.fault_message()
        wait_for(lambda: "OPERATION ENABLED" not in drive.drive_states())
