"""The drive loop of `cncctl identify`: one axis's excitation streamed to an open drive, the
commanded and encoder position of every sample recorded.

A small loop on the Drive API rather than the job pipeline: the excitation is made of
positions already (no program, no planning), and what the fit needs is each frame's
commanded and measured position, which `Drive.feedback()` returns per frame. It keeps the
FIFO between a few cycles and the config's high water, supervises the following error (the
LinuxCNC rule of the axis), the drive status and the e-stop input, and on a stop request
ends the excitation along its own path (`Excitation.fade_out`: back to the start point at
rest within TAPER_S), never by dropping frames mid-motion.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from controller.config import AxisConfig, MachineConfig
from controller.servo.excitation import Excitation
from drivers.base import Drive
from drivers.errors import DriveError

CYCLE_S = 0.01  # one loop cycle: ten frames at 1 ms
LEAD_IN_S = 0.05  # at rest before the excitation: the encoder's offset is read there
TAIL_S = 0.3  # at rest after it: the loop's settling is part of the record
DRAIN_TIMEOUT_S = 5.0  # frames all written, the rest must be clocked within this
QUIET_CYCLES = 5  # the FIFO empty and no report for this many cycles: the record is whole


@dataclass(frozen=True, eq=False)
class AxisRecord:
    """One axis's run: per executed frame, its commanded and encoder counts."""

    axis: str
    commanded_counts: np.ndarray  # (n,) int64: every sample sent
    sample_index: np.ndarray  # (m,) the samples the drive reported (a serial card: some)
    encoder_counts: np.ndarray  # (m,) int64: the encoder at those samples
    rest_samples: int  # the lead-in at rest
    stopped: str | None  # why the excitation ended early (None: it ran whole)
    fault: str | None  # a drive fault or following error (the drive latched or was stopped)


class StopRequest:
    """An operator's stop (Ctrl-C, SIGTERM): read by the loop between cycles."""

    def __init__(self) -> None:
        self.reason: str | None = None
        self._event = threading.Event()

    def request_abort(self, reason: str) -> None:
        if self.reason is None:
            self.reason = reason
        self._event.set()


def reference_counts(excitation: Excitation, start_count: int, pulse_mm: float) -> np.ndarray:
    """Absolute commanded counts per sample: lead-in, excitation, tail, all from start."""
    lead = int(round(LEAD_IN_S / excitation.sample_period_s))
    tail = int(round(TAIL_S / excitation.sample_period_s))
    rel = np.r_[np.zeros(lead), excitation.position_mm, np.zeros(tail)]
    return start_count + np.rint(rel / pulse_mm).astype(np.int64)


def excite_axis(drive: Drive, config: MachineConfig, axis_index: int, excitation: Excitation,
                stop: StopRequest, virtual_time: bool,
                beat: Callable[[], None] | None = None) -> AxisRecord:
    """Run the excitation on one axis (the others hold), return what was recorded; beat, if
    given, is called every loop turn (the daemon's watchdog sees the loop alive)."""
    axis = config.axes[axis_index]
    period_s = config.sample_period_s
    cmd0, _ = drive.position_counts()
    drive.feedback()  # earlier frames' rows are not this record's
    counts = reference_counts(excitation, int(cmd0[axis_index]), axis.pulse_mm)
    lead = int(round(LEAD_IN_S / period_s))
    cycle = max(1, int(round(CYCLE_S / period_s)))
    high = max(4 * cycle, int(config.runtime.card_fifo_high_water_ms / 1000.0 / period_s))
    high = min(high, drive.fifo_capacity() - 1)
    sent, faded, prev = 0, False, int(cmd0[axis_index])
    seq_rows: list[np.ndarray] = []
    cmd_rows: list[np.ndarray] = []
    enc_rows: list[np.ndarray] = []
    fault: str | None = None
    deadline_s: float | None = None
    idle_s = 0.0

    def take() -> int:
        fb = drive.feedback()
        if len(fb):
            seq_rows.append(fb.seq.copy())
            cmd_rows.append(fb.commanded_counts[:, axis_index].copy())
            enc_rows.append(fb.encoder_counts[:, axis_index].copy())
        return len(fb)

    got, quiet = 0, 0
    while True:
        if beat is not None:
            beat()
        fresh = take()
        got += fresh
        status = drive.status()
        if status.halted:
            fault = drive.fault_message() or str(status)
            break
        if fault is None and got:
            fault = _ferror(cmd_rows[-1], enc_rows[-1], axis, period_s)
            if fault is not None:
                stop.request_abort(fault)
        if drive.estop_input():
            stop.request_abort("the e-stop input tripped")
        limit = drive.limit_input()
        if limit is not None:
            stop.request_abort(f"hard limit: {limit} tripped")
        if stop.reason is not None and not faded:
            counts = _faded(counts, excitation, sent, lead, axis.pulse_mm)
            faded = True
        if sent < len(counts):
            room = high - drive.fifo_level()
            if room > 0:
                chunk = counts[sent:sent + room]
                frames = np.zeros((len(chunk), len(config.axes)), dtype=np.int64)
                frames[:, axis_index] = np.diff(chunk, prepend=prev)
                drive.write_frames(frames, end_of_stream=sent + len(chunk) >= len(counts))
                prev, sent = int(chunk[-1]), sent + len(chunk)
        elif drive.fifo_level() == 0:
            quiet = quiet + 1 if not fresh else 0  # the last reports may still be on the way
            if quiet >= QUIET_CYCLES:
                break
        else:
            deadline_s = deadline_s if deadline_s is not None else idle_s + DRAIN_TIMEOUT_S
            if idle_s > deadline_s:
                fault = f"frames still queued {DRAIN_TIMEOUT_S:g} s after the last was sent"
                break
        idle_s += cycle * period_s
        if virtual_time:
            drive.advance(cycle)  # type: ignore[attr-defined]  (the sim card in virtual time)
        else:
            time.sleep(CYCLE_S)
    if stop.reason is not None and "e-stop" in stop.reason:
        _disable(drive)
    empty = np.zeros(0, dtype=np.int64)
    seq, cmd, enc = (np.concatenate(r) if r else empty for r in (seq_rows, cmd_rows, enc_rows))
    index = _align(counts, seq, cmd)
    if index is None and fault is None and stop.reason is None:
        fault = "the drive's feedback does not match the frames sent"
    if index is None:
        index, enc = empty, empty
    return AxisRecord(axis.name, counts, index, enc, lead, stop.reason, fault)


def _align(counts: np.ndarray, seq: np.ndarray, cmd: np.ndarray) -> np.ndarray | None:
    """Each feedback row's sample in `counts`: the offset between the drive's frame numbers
    and ours is the one under which every row's commanded counts are the ones sent (the
    first row a drive reports need not be the first frame). None when no offset fits."""
    if not len(seq):
        return None
    rel = seq - seq[0]
    if rel.min() < 0 or rel.max() >= len(counts):
        return None
    for first in range(0, len(counts) - int(rel.max())):
        index = rel + first
        if np.array_equal(counts[index], cmd):
            return index
    return None


def _faded(counts: np.ndarray, excitation: Excitation, sent: int, lead: int,
           pulse_mm: float) -> np.ndarray:
    """The counts with the excitation ended early from sample `sent` (frames already sent
    are kept): the fade-out, then the rest of the tail at the start point."""
    start = counts[0]
    k = sent - lead
    if k < 0:
        return counts[:max(sent, 1)]  # still at rest: end here
    if k >= len(excitation.position_mm):
        return counts  # in the tail: at rest already
    fade = start + np.rint(excitation.fade_out(k) / pulse_mm).astype(np.int64)
    tail = np.full(int(round(TAIL_S / excitation.sample_period_s)), start, dtype=np.int64)
    return np.r_[counts[:sent], fade, tail]


def _ferror(cmd: np.ndarray, enc: np.ndarray, axis: AxisConfig, period_s: float) -> str | None:
    """The LinuxCNC following-error rule over the latest frames (None: within it)."""
    err = np.abs(cmd - enc) * axis.pulse_mm
    v = np.abs(np.diff(cmd, prepend=cmd[:1])) * axis.pulse_mm / period_s
    limit = np.maximum(axis.min_ferror_mm, axis.ferror_mm * v / axis.max_velocity_mm_s)
    bad = np.flatnonzero(err > limit)
    if not len(bad):
        return None
    i = int(bad[0])
    return f"{axis.name.upper()} following error {err[i]:.3f} mm over its limit {limit[i]:.3f} mm"


def _disable(drive: Drive) -> None:
    """The e-stop's second half once the faded frames are clocked: the axes powered off."""
    try:
        drive.disable()
    except DriveError:
        pass
