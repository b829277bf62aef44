"""The serial backend against the simulated card in its own process: bring-up, run, faults.

The card is `cncctl simdrive serial`; the airfoil is streamed to the end, and every injected
fault ends in a controlled stop or a latched fault within a stated time."""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller.config import load_config
from controller.errors import DriveError
from controller.operator.cli import main
from drivers.base import CardStatus
from drivers.errors import LostCommunicationError
from drivers.registry import make_drive
from drivers.serial import protocol as p
from drivers.serial.backend import SerialCard
from drivers.serial.sim_peer import PeerCard

REPO = Path(__file__).resolve().parents[2]
NACA = str(REPO / "nc_programs" / "naca2415.nc")
CLI = [sys.executable, "-m", "controller.operator.cli"]
T_S = 0.001
HIGH_WATER_S = 0.100 + 2 * T_S  # the motion loop keeps at most this much queued (+1 cycle)
STATUS_S = 0.010
LINK_TIMEOUT_S = 3 * STATUS_S
LINK_S = 0.1
DETECT_S = 0.050  # a latched card fault stops the host's streaming within this (report, cycle)


def _readline(stream: Any, timeout_s: float) -> str:
    """One line of an unbuffered binary pipe (nothing is held back in a Python buffer, so
    select() sees every line that has arrived)."""
    ready, _, _ = select.select([stream], [], [], timeout_s)
    assert ready, f"no line within {timeout_s} s"
    return stream.readline().decode()


@contextmanager
def peer(*options: str, config: str = "serial") -> Iterator[tuple[str, subprocess.Popen[bytes]]]:
    """A simulated card process; always killed (by pid) and reaped on the way out."""
    args = ["--config", config, *(a for o in options for a in ("--option", o))]
    proc = subprocess.Popen([*CLI, "simdrive", "serial", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, bufsize=0, cwd=REPO)
    try:
        path = _readline(proc.stdout, 20.0).strip()
        assert path.startswith("/dev/"), (path, proc.stderr.read() if proc.poll() else "")
        yield path, proc
    finally:
        proc.kill()
        proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()


def run_airfoil(port: str, during: Callable[[dict[str, Any]], None] | None = None
                ) -> tuple[int, dict[str, Any], str]:
    """`cncctl run naca2415 --config serial --json`: (exit code, final event, stderr);
    `during` sees each JSON event as it arrives. Checks nothing of it is left running.

    The runs pass a link timeout of LINK_S (the default, 100 ms, is tested in
    test_silent_card_is_a_lost_link_after_the_link_timeout): on a loaded 2-core machine the
    simulated card's pty stalled for up to 100 ms even with the card at SCHED_FIFO.
    """
    extra = ["--drive-option", f"link_timeout_s={LINK_S}"]
    proc = subprocess.Popen([*CLI, "run", NACA, "--config", "serial", "--json",
                             "--drive-option", f"port={port}", *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, bufsize=0, cwd=REPO, start_new_session=True)
    try:
        events = []
        deadline_s = time.monotonic() + 30.0
        while (line := _readline(proc.stdout, max(0.1, deadline_s - time.monotonic()))):
            events.append(json.loads(line))
            if during is not None:
                during(events[-1])
        code = proc.wait(timeout=10)
        err = proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()
    # Its interpreter and generator are gone; multiprocessing's resource tracker may take a
    # moment to see its parent's exit and leave.
    deadline_s = time.monotonic() + 3.0
    while (live := _running_in_group(proc.pid)) and time.monotonic() < deadline_s:
        time.sleep(0.01)
    assert live == [], [Path(f"/proc/{pid}/cmdline").read_bytes() for pid in live]
    assert events and events[-1]["event"] in ("done", "fault", "aborted"), err
    return code, events[-1], err


def _running_in_group(pgid: int) -> list[int]:
    """Live (not zombie) processes of a process group. A child the run left to init can stay
    a zombie in a container whose init does not reap; it runs nothing."""
    live = []
    for entry in Path("/proc").iterdir():
        try:
            fields = (entry / "stat").read_text().rpartition(")")[2].split()
        except (OSError, ValueError):
            continue
        if entry.name.isdigit() and int(fields[2]) == pgid and fields[0] != "Z":
            live.append(int(entry.name))
    return live


# -- the card's logic in-process (no pty) ---------------------------------------------------
def _card(**options: Any) -> tuple[PeerCard, list[p.Status]]:
    sent: list[p.Status] = []
    dec = p.Decoder(p.CARD_SYNC)
    card = PeerCard(load_config("serial"), options,
                    lambda data: sent.extend(dec.feed(data)))  # type: ignore[arg-type]
    return card, sent


def test_card_latches_sequence_gap_bad_crc_and_underrun_until_reset() -> None:
    card, sent = _card()
    card.handle_bytes(p.encode_sample(10, (5, -5)) + p.encode_sample(12, (5, -5)))
    card.send_status()
    assert sent[-1].latched == p.ST_SEQ_GAP and sent[-1].fifo_level == 1
    card.handle_bytes(p.encode_reset(7))
    assert sent[-1].reply_to == 7 and sent[-1].latched == 0 and sent[-1].fifo_level == 0
    bad = bytearray(p.encode_sample(13, (1, 1)))
    bad[6] ^= 1
    card.handle_bytes(bytes(bad))
    card.handle_bytes(p.encode_status_request(8))
    assert sent[-1].latched == p.ST_BAD_FRAME and sent[-1].fifo_level == 0
    card.handle_bytes(p.encode_reset(9) + p.encode_sample(20, (3, 4)) + p.encode_sample(21, (3, 4)))
    card.clock(3)  # two frames, then empty mid-stream: the hostmot2 rule
    card.send_status()
    assert sent[-1].latched & p.ST_UNDERRUN and sent[-1].exec_seq == 21
    assert sent[-1].commanded == (6, 8)


def test_card_after_end_of_stream_is_idle_not_underrun() -> None:
    card, sent = _card()
    card.handle_bytes(p.encode_sample(0, (1, 0)) + p.encode_sample(1, (1, 0)) + p.encode_end())
    card.clock(50)
    card.send_status()
    assert sent[-1].latched == 0 and sent[-1].commanded == (2, 0)


def test_card_process_prints_its_port_first_and_exits_0_on_sigterm() -> None:
    with peer() as (port, proc):
        assert os.path.exists(port)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0


def test_a_report_gives_the_last_sample_and_the_one_before() -> None:
    """Two rows per report: the following-error check then sees a one-period velocity (its
    limit grows with speed; over a whole status period the speed would read 10 times high)."""
    drive = SerialCard(load_config("serial"), port="/dev/null")
    drive._written, drive._synced = 100, True  # as after open() and 100 frames written
    status = p.Status(0, 40, 256, p.ST_EXECUTED, 0, 0, 99, 59, (580, -10), (560, -9), (58, -1),
                      (57, 0))
    drive._on_status(status, time.monotonic())
    drive._is_open = True
    fb = drive.feedback()
    assert fb.seq.tolist() == [58, 59]
    assert fb.commanded_counts.tolist() == [[522, -9], [580, -10]]
    assert fb.encoder_counts.tolist() == [[503, -9], [560, -9]]
    drive._on_status(replace(status, latched=0), time.monotonic())  # nothing new executed
    assert len(drive.feedback()) == 0
    assert 35 <= drive.fifo_level() <= 40  # the report's level, less the periods since


def test_unknown_peer_option_is_named() -> None:
    with pytest.raises(DriveError, match="'lag_m'"):
        _card(lag_m=1.0)


# -- bring-up ---------------------------------------------------------------------------------
def test_check_without_a_card_says_so_and_exits_2(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "ttyUSB9"
    assert main(["check", NACA, "--config", "serial", "--drive-option", f"port={missing}"]) == 2
    assert str(missing) in capsys.readouterr().err


def test_probe_of_a_port_where_nothing_answers_fails_in_bounded_time() -> None:
    master, slave = os.openpty()
    try:
        drive = make_drive(load_config("serial"), port=os.ttyname(slave), reply_timeout_s=0.2)
        t0 = time.monotonic()
        with pytest.raises(DriveError, match="no serial card answering on /dev/"):
            drive.probe()
        assert time.monotonic() - t0 < 1.0
    finally:
        os.close(master)
        os.close(slave)


def test_options_are_strict_and_virtual_time_is_refused() -> None:
    cfg = load_config("serial")
    with pytest.raises(DriveError, match="'baud'"):
        make_drive(cfg, baud=9600)
    with pytest.raises(DriveError, match="virtual time"):
        make_drive(cfg, realtime=False)
    with pytest.raises(DriveError, match="'status_period_s'"):
        make_drive(cfg, status_period_s="fast")


def test_bring_up_stream_underrun_and_reset() -> None:
    cfg = load_config("serial")
    with peer() as (port, _):
        make_drive(cfg, port=port).probe()
        with pytest.raises(DriveError, match="512"):
            make_drive(cfg, port=port, fifo_frames=512).probe()
        drive = make_drive(cfg, port=port, realtime=True)
        with drive:
            assert drive.status() == CardStatus.OK and drive.fifo_level() == 0
            drive.write_frames(np.tile([5, -5], (50, 1)), end_of_stream=True)
            rows = _wait_rows(drive, 49)
            assert np.array_equal(rows[-1][1], [250, -250]) and drive.status() == CardStatus.OK
            assert all(0 <= s < 50 for s, _ in rows)
            drive.write_frames(np.tile([1, 1], (20, 1)))  # no end of stream: underrun
            rows = _wait_rows(drive, 69)
            deadline_s = time.monotonic() + 1.0
            while drive.status() == CardStatus.OK and time.monotonic() < deadline_s:
                time.sleep(STATUS_S / 2)
            assert drive.status() == CardStatus.UNDERRUN
            assert "underrun" in drive.fault_message() and "after frame 69" in drive.fault_message()
            drive.reset()
            assert drive.status() == CardStatus.OK
            assert drive.link_stats()["rtt_s"]  # the reset's reply at least


def _wait_rows(drive: Any, last_seq: int) -> list[tuple[int, np.ndarray]]:
    rows: list[tuple[int, np.ndarray]] = []
    deadline_s = time.monotonic() + 2.0
    while (not rows or rows[-1][0] < last_seq) and time.monotonic() < deadline_s:
        fb = drive.feedback()
        rows += [(int(s), c) for s, c in zip(fb.seq, fb.commanded_counts, strict=True)]
        time.sleep(STATUS_S / 2)
    assert rows and rows[-1][0] == last_seq
    return rows


def test_three_axes_stream_with_int16_samples() -> None:
    cfg = load_config("xyz_mill")
    with peer(config="xyz_mill") as (port, _):
        drive = SerialCard(cfg, port=port)  # the config's own backend is sim
        with drive:
            drive.write_frames(np.tile([1, -200, 300], (10, 1)), end_of_stream=True)
            rows = _wait_rows(drive, 9)
            assert np.array_equal(rows[-1][1], [10, -2000, 3000])
            assert drive.status() == CardStatus.OK


def test_silent_card_is_a_lost_link_after_the_link_timeout() -> None:
    with peer("silent_after_s=0") as (port, _):  # silent from the first sample on
        drive = make_drive(load_config("serial"), port=port)
        with drive:
            drive.write_frames(np.zeros((1, 2), dtype=np.int64), end_of_stream=True)
            t0 = time.monotonic()
            with pytest.raises(LostCommunicationError, match="no valid status") as info:
                while time.monotonic() - t0 < 1.0:
                    drive.status()
                    time.sleep(0.001)
    silent_ms = int(re.search(r"for (\d+) ms \(limit 100 ms", str(info.value)).group(1))
    assert 100 <= silent_ms <= 100 + 15  # polled every ms; told within the 100 ms default


def test_killed_card_is_a_lost_link_within_a_status_period() -> None:
    with peer() as (port, proc):
        drive = make_drive(load_config("serial"), port=port)
        with drive:
            assert drive.status() == CardStatus.OK
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            t0 = time.monotonic()
            with pytest.raises(LostCommunicationError, match=f"{port} lost: "):
                while time.monotonic() - t0 < 1.0:
                    drive.feedback()
                    time.sleep(0.001)
            assert time.monotonic() - t0 < LINK_TIMEOUT_S


# -- the airfoil across processes -------------------------------------------------------------
def test_airfoil_runs_to_the_end_like_the_sim_card(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", NACA, "--json", "--virtual-time"]) == 0
    sim = json.loads(capsys.readouterr().out.splitlines()[-1])
    with peer() as (port, _):
        code, final, err = run_airfoil(port)
    assert code == 0 and final["event"] == "done", (final, err)
    for key in ("pulses", "final_position_mm", "underruns", "position_known", "line"):
        assert final[key] == sim[key], key
    assert all(v["commanded"] == v["executed"] for v in final["pulses"].values())
    assert final["planned_time_s"] == sim["planned_time_s"]
    assert abs(final["motion_time_s"] - sim["motion_time_s"]) < 2 * STATUS_S


def _bounded(final: dict[str, Any], fault_at_s: float, detect_s: float) -> None:
    """The host stopped streaming within detect_s of the fault: what it sent ends there."""
    assert final["planned_time_s"] <= fault_at_s + HIGH_WATER_S + detect_s, final


def test_drive_fault_latches_and_names_the_axis() -> None:
    with peer("drive_fault_after_frames=400") as (port, _):
        code, final, _ = run_airfoil(port)
    assert code == 3 and final["message"] == "X axis drive fault 0x2310"
    assert final["position_known"] and final["final_position_mm"]["x"] < -1.0
    _bounded(final, 0.400, DETECT_S)


def test_following_error_is_a_controlled_stop_along_the_path() -> None:
    with peer("lag_mm=2.0", "lag_after_frames=400") as (port, _):
        code, final, _ = run_airfoil(port)
    assert code == 3 and final["message"].startswith("X axis following error")
    # Controlled: every frame of the stop was executed, nothing was left in the card.
    assert all(v["commanded"] == v["executed"] for v in final["pulses"].values())
    stop_s = 15 * 100.0 / (8 * 2450.0) + 0.01  # holdback: the longest stop along the path
    _bounded(final, 0.420, DETECT_S + stop_s)


def test_silent_card_is_a_lost_link_with_the_last_known_position() -> None:
    with peer("silent_after_s=0.4") as (port, _):
        code, final, _ = run_airfoil(port)
    assert code == 3 and final["message"].startswith("no valid status from the card on")
    assert not final["position_known"] and final["final_position_mm"]["x"] < -1.0
    assert final["planned_time_s"] >= 0.400  # not tripped before the card fell silent
    _bounded(final, 0.400, LINK_S + DETECT_S)


def test_card_killed_mid_run_is_a_fault_not_a_hang() -> None:
    killed: list[float] = []
    with peer() as (port, proc):
        def kill_when_moving(event: dict[str, Any]) -> None:
            if event["event"] == "progress" and event["executed_s"] > 0 and not killed:
                proc.send_signal(signal.SIGKILL)
                killed.append(time.monotonic())
        code, final, _ = run_airfoil(port, during=kill_when_moving)
        assert killed, f"the run ended before the card was killed: {final}"
        ended_s = time.monotonic() - killed[0]
    assert code == 3 and "serial link to the card on" in final["message"]
    assert "lost" in final["message"] and not final["position_known"]
    assert final["motion_time_s"] < 1.137  # it did not run to the end unseen
    assert ended_s < 2.0  # detection, then the runtime's teardown


def test_bad_crc_from_the_host_side_latches_bad_frame() -> None:
    with peer("corrupt_rx_after_frames=400") as (port, _):
        code, final, _ = run_airfoil(port)
    assert code == 3 and "received a bad frame (bad CRC" in final["message"]
    assert final["position_known"]
    # Frame 400 is corrupted as it arrives: the host has sent 400 frames then.
    assert final["planned_time_s"] <= 0.400 + DETECT_S


def test_lost_frame_latches_a_sequence_gap() -> None:
    with peer("drop_frame_after_frames=400") as (port, _):
        code, final, _ = run_airfoil(port)
    assert code == 3 and "sequence gap after frame 399" in final["message"]
    assert final["planned_time_s"] <= 0.400 + DETECT_S


def test_bad_crc_from_the_card_is_a_lost_link() -> None:
    with peer("corrupt_status_after_s=0.4") as (port, _):
        code, final, _ = run_airfoil(port)
    assert code == 3 and "status frames with bad CRC" in final["message"]
    assert "0 status frames" not in final["message"] and not final["position_known"]
    assert final["planned_time_s"] >= 0.400
    _bounded(final, 0.400, LINK_S + DETECT_S)


def test_a_second_process_on_the_port_is_refused_and_the_job_runs_on(tmp_path: Path) -> None:
    """A second `cncctl run` or `check` on the port of a moving job used to open it too: its
    reset emptied the card's FIFO and the table stopped dead, 3 mm off the path. The job
    waits at an M0 while the others try (an airfoil of 1.1 s could end before a second
    process had even started on a loaded machine, and then `check` rightly opened the port)."""
    program = tmp_path / "m0.nc"
    program.write_text("G21 G90 G64 F2400\nG1 X5\nM0\nG1 X0\nM2\n")
    with peer() as (port, _):
        proc = subprocess.Popen([*CLI, "run", str(program), "--config", "serial", "--json",
                                 "--drive-option", f"port={port}", "--drive-option",
                                 f"link_timeout_s={LINK_S}"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                cwd=REPO)
        try:
            assert proc.stdout is not None and proc.stdin is not None
            while (event := json.loads(proc.stdout.readline()))["event"] != "progress" \
                    or event["state"] != "paused":
                assert event["event"] in ("start", "progress"), event
            second = [subprocess.run([*CLI, command, NACA, "--config", "serial",
                                      "--drive-option", f"port={port}"], capture_output=True,
                                     text=True, timeout=60, cwd=REPO)
                      for command in ("run", "check")]
            assert proc.poll() is None  # still paused: the port was in use all along
            proc.stdin.write("\n")
            proc.stdin.flush()
            out, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        final = json.loads(out.splitlines()[-1])
        assert (proc.returncode, final["event"]) == (0, "done"), err
        assert final["underruns"] == 0
        assert final["final_position_mm"] == {"x": 0.0, "y": 0.0}
        assert [r.returncode for r in second] == [2, 2], [r.stderr for r in second]
        for r in second:
            assert "in use by another controller process" in r.stderr, r.stderr
            assert "Traceback" not in r.stderr


def test_an_embedded_run_starts_where_the_card_stands(tmp_path: Path) -> None:
    """The card keeps its position between runs, as hardware does: the second run used to be
    planned from X0 Y0 (a fault, or 'done' with nothing moved for a G0 X0 Y0)."""
    out_there, back = tmp_path / "a.nc", tmp_path / "b.nc"
    out_there.write_text("G21 G90\nG0 X5 Y5\nM2\n")
    back.write_text("G21 G90\nG0 X0 Y0\nM2\n")
    with peer() as (port, _):
        finals = []
        for program in (out_there, out_there, back):
            done = subprocess.run([*CLI, "run", str(program), "--config", "serial", "--json",
                                   "--drive-option", f"port={port}", "--drive-option",
                                   f"link_timeout_s={LINK_S}"], capture_output=True, text=True,
                                  timeout=60, cwd=REPO)
            assert done.returncode == 0, done.stderr
            finals.append(json.loads(done.stdout.splitlines()[-1]))
    assert [f["final_position_mm"] for f in finals] == [
        {"x": 5.0, "y": 5.0}, {"x": 5.0, "y": 5.0}, {"x": 0.0, "y": 0.0}]
    assert finals[2]["motion_time_s"] > 0.1  # it moved back
