"""Homing on CiA 402 drives: mode 6 (methods 1/2/17/18), then CSP again and the final move."""

from __future__ import annotations

import contextlib
import time
from typing import Any

import numpy as np

from controller.errors import DriveError
from drivers.canopen import bringup
from drivers.canopen import cia402 as c
from drivers.canopen.link import Link
from drivers.errors import HomingError
from drivers.homing import HomingPlan, move_frames, plan_for

HOST_LIMIT_MARGIN_MM = 5.0  # the host stops a drive this far beyond the search limit
STOP_WAIT_S = 2.0  # after a halt: how long the axes may take to stand still
SETTLE_WAIT_S = 1.0  # after the final move: encoder within a pulse of the step counter

# drivers.canopen.backend.CanopenDrive (not imported: the backend imports this module).
CanopenDrive = Any


def home(drive: CanopenDrive, axes: tuple[int, ...], timeout_s: float) -> None:
    """Run the homing method of each axis's drive together (HomingError naming the axis)."""
    link: Link = drive._check_comm()
    plans = {i: plan_for(drive.config, i) for i in axes}
    deadline_s = time.monotonic() + timeout_s
    for i in axes:
        _guard(drive, i, lambda i=i: _configure(drive, i, plans[i]))
    failure: HomingError | None = None
    try:
        _start(drive, link, axes)
        _wait(drive, link, axes, plans, deadline_s, timeout_s)
    except HomingError as exc:
        failure = exc
    _back_to_csp(drive, link, axes, halt=failure is not None)
    if failure is not None:
        raise failure
    with link.lock:
        for i in axes:
            link.rebooted[i] = False
    _final_move(drive, link, axes, plans, deadline_s)


def _guard(drive: CanopenDrive, i: int, action: Any) -> Any:
    """An SDO failure while homing is a HomingError naming the axis."""
    try:
        return action()
    except HomingError:
        raise
    except DriveError as exc:
        name = drive.axes[i]
        raise HomingError(f"{name.upper()} axis homing failed: {exc}", name) from exc


def _configure(drive: CanopenDrive, i: int, plan: HomingPlan) -> None:
    node, name, cpm = drive._nodes[i], drive.axes[i], drive.o.counts_per_mm[i]
    modes = bringup.sdo_read(node, name, c.SUPPORTED_MODES, None, "supported modes")
    if not modes & c.SUPPORTS_HOMING:
        raise HomingError(f"{name.upper()} axis homing failed: {bringup.label(node, name)} "
                          f"has no homing mode (0x6502 = 0x{modes:08X}, bit 5 clear)", name)
    method = c.HOMING_METHODS[(plan.direction, plan.use_index)]
    writes = ((c.HOMING_METHOD, None, method, "homing method"),
              (c.HOMING_SPEEDS, 1, _counts(plan.search_mm_s, cpm), "search speed, counts/s"),
              (c.HOMING_SPEEDS, 2, _counts(plan.latch_mm_s, cpm), "zero speed, counts/s"),
              (c.HOMING_ACCEL, None, _counts(plan.accel_mm_s2, cpm), "acceleration, counts/s2"),
              (c.HOME_OFFSET, None, drive.o.home_offset_sign * round(plan.home_mm * cpm),
               "home offset, counts"))
    for index, sub, value, what in writes:
        bringup.sdo_write(node, name, index, sub, value, what)


def _counts(value: float, cpm: float) -> int:
    return max(1, round(value * cpm))


def _set_mode(drive: CanopenDrive, i: int, mode: int, what: str) -> None:
    node, name = drive._nodes[i], drive.axes[i]
    bringup.sdo_write(node, name, c.MODE, None, mode, f"mode of operation: {what}")
    shown = bringup.sdo_read(node, name, c.MODE_DISPLAY, None, "mode of operation display")
    if shown != mode:
        raise DriveError(f"{bringup.label(node, name)}: did not switch to {what} mode: 0x6061 "
                         f"reads {shown} after writing {mode} to 0x6060")


def _cycles(link: Link, n: int) -> None:
    """Wait until n more SYNC cycles have been sent (RPDO1 carries a new controlword)."""
    target = link.cycle_no + n
    deadline_s = time.monotonic() + 1.0 + n * link.period_s * 4
    while link.cycle_no < target and time.monotonic() < deadline_s:
        time.sleep(link.period_s)


def _start(drive: CanopenDrive, link: Link, axes: tuple[int, ...]) -> None:
    for i in axes:
        drive._nodes[i].controlword = c.CW_ENABLE_OPERATION  # bit 4 low: an edge to come
        _guard(drive, i, lambda i=i: _set_mode(drive, i, c.MODE_HOMING, "homing"))
    _cycles(link, 2)
    for i in axes:
        drive._nodes[i].controlword = c.CW_ENABLE_OPERATION | c.CW_HOMING_START


def _wait(drive: CanopenDrive, link: Link, axes: tuple[int, ...],
          plans: dict[int, HomingPlan], deadline_s: float, timeout_s: float) -> None:
    """Until every drive says homing attained (bits 12 and 10), or an error, fault, limit."""
    with link.lock:
        start_cycle = link.cycle_no
        start = {i: link.counts[i] for i in axes}
    pending = set(axes)
    while pending:
        time.sleep(2 * link.period_s)
        with link.lock:
            status, messages = link.status, "; ".join(link.messages)
            fresh = {i: link.last_tpdo_cycle[i] > start_cycle + 2 for i in axes}
            sw = list(link.statusword)
            counts = list(link.counts)
        if status.halted:
            i = next((i for i in axes if c.state_of(sw[i]) == "FAULT"), min(pending))
            raise _error(drive, i, f"drive fault during homing: {messages}")
        for i in sorted(pending):
            if not fresh[i]:
                continue
            if sw[i] & c.SW_HOMING_ERROR:
                raise _error(drive, i, f"the drive reports a homing error (0x6041 = "
                             f"0x{sw[i]:04X}, bit 13): home switch not found within its "
                             "search range, or the method was refused")
            if sw[i] & c.SW_HOMING_ATTAINED and sw[i] & c.SW_TARGET_REACHED:
                pending.discard(i)
                continue
            limit_mm = plans[i].search_limit_mm + HOST_LIMIT_MARGIN_MM
            if abs(counts[i] - start[i]) / drive.o.counts_per_mm[i] > limit_mm:
                raise _error(drive, i, f"home switch not found within {limit_mm:.1f} mm "
                             "(the travel + 10 %, and the drive did not stop): halted")
        if pending and time.monotonic() > deadline_s:
            raise _error(drive, min(pending), f"time-out: not homed within {timeout_s:g} s "
                         "(halted)")
        reason = drive.homing_aborted()
        if pending and reason:
            raise _error(drive, min(pending), f"{reason} (halted)")


def _error(drive: CanopenDrive, i: int, reason: str) -> HomingError:
    name = drive.axes[i]
    return HomingError(f"{name.upper()} axis homing failed: {reason}", name)


def _back_to_csp(drive: CanopenDrive, link: Link, axes: tuple[int, ...], halt: bool) -> None:
    """Halt (on failure) and wait for standstill, hand the drive's own demand over to the
    host's step counter (bumpless), then cyclic synchronous position mode again. After a
    latched fault the controlwords are the link's (quick stop): only the mode is set back."""
    with link.lock:
        halted = link.status.halted
    for i in axes:
        if not halted:
            drive._nodes[i].controlword = c.CW_ENABLE_OPERATION | (c.CW_HALT if halt else 0)
    if halt and not halted:
        deadline_s = time.monotonic() + STOP_WAIT_S
        while time.monotonic() < deadline_s:
            _cycles(link, 5)
            with link.lock:
                if all(link.statusword[i] & c.SW_TARGET_REACHED for i in axes):
                    break
    demands = {}
    for i in axes:
        with contextlib.suppress(DriveError):  # a drive gone: reset() or close() follow
            demands[i] = bringup.sdo_read(drive._nodes[i], drive.axes[i], c.POSITION_DEMAND,
                                          None, "position demand")
    link.rebase_axes(demands)
    # The SYNC thread builds a cycle's RPDO1s under the lock and sends them after it: one built
    # before the rebase, with the step counter of before homing, could reach a drive after
    # the mode change below, and the jump of its target tripped the drive's following error
    # (EMCY 0x8611) now and then. Two more cycles: every RPDO1 in flight carries the rebase.
    _cycles(link, 2)
    for i in axes:
        if not halted:
            drive._nodes[i].controlword = c.CW_ENABLE_OPERATION
        if halt:
            with contextlib.suppress(DriveError):
                _set_mode(drive, i, c.MODE_CSP, "cyclic synchronous position")
        else:
            _guard(drive, i, lambda i=i: _set_mode(drive, i, c.MODE_CSP,
                                                   "cyclic synchronous position"))


def _final_move(drive: CanopenDrive, link: Link, axes: tuple[int, ...],
                plans: dict[int, HomingPlan], deadline_s: float) -> None:
    """From the home point to final_mm in CSP, through the host FIFO (not a stream: no
    sequence numbers are used, no feedback rows are kept)."""
    with link.lock:
        start = link.cmd.copy()
    target = start.copy()
    v, a = np.ones(drive.n_axes), np.ones(drive.n_axes)
    for i in axes:
        plan = plans[i]
        final_mm = plan.final_mm if plan.final_mm is not None else plan.home_mm
        target[i] = round(final_mm / drive.pulse_mm[i])
        v[i], a[i] = plan.search_mm_s, plan.accel_mm_s2
    frames = move_frames(start, target, v, a, drive.pulse_mm, drive.period_s)
    sent = 0
    while sent < len(frames) or len(link.fifo):
        with link.lock:
            if link.status.halted:
                raise _error(drive, min(axes), "drive fault during the move to final_mm: "
                             + "; ".join(link.messages))
            room = link.fifo.capacity - len(link.fifo)
            if sent < len(frames) and room:
                chunk = frames[sent:sent + room]
                sent += len(chunk)
                link.fifo.push(chunk, link.written, sent == len(frames))
                link.streaming = True  # until the last frame (end of stream) is taken
        if time.monotonic() > deadline_s + SETTLE_WAIT_S:
            raise _error(drive, min(axes), "time-out during the move to final_mm")
        time.sleep(0.01)
    settle_s = time.monotonic() + SETTLE_WAIT_S
    while time.monotonic() < settle_s:
        with link.lock:
            if not link.rows and not np.abs(link.enc - link.cmd)[list(axes)].any():
                break
        time.sleep(link.period_s)
    link.take_trace()  # rows of the move: not the motion controller's
