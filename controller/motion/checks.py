"""Per-frame checks of executed motion: following error (LinuxCNC rule) and contour error."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from controller.motion.stopping import REST_SPEED_MM_S
from controller.numeric import polyline_distance
from drivers.base import Feedback


class RefHistory:
    """Reference rows of frames sent but maybe not yet executed, indexed by frame sequence."""

    def __init__(self, capacity: int, n_axes: int, period_s: float) -> None:
        self.capacity = capacity
        self.period_s = period_s
        self.pos_mm = np.zeros((capacity, n_axes))
        self.feed_mm_s = np.zeros(capacity)
        self.line = np.zeros(capacity, dtype=np.int64)
        self.phi_rad = np.full(capacity, np.nan)  # path tangent angle; NaN when at rest
        # The card's step counter after each frame (what went out, pre-compensated and
        # rounded to pulses): the model watch runs the servo model on it.
        self.cmd_counts = np.zeros((capacity, n_axes), dtype=np.int64)
        self.count = 0

    def append(self, pos_mm: np.ndarray, feed_mm_s: np.ndarray, line: np.ndarray,
               prev_mm: np.ndarray, cmd_counts: np.ndarray | None = None) -> None:
        d = pos_mm - np.concatenate((prev_mm[None, :], pos_mm[:-1]))  # (np.diff of a vstack)
        # Below the rest speed the tangent is undefined: no contour error is measured there.
        moving = np.hypot(d[:, 0], d[:, 1]) / self.period_s >= REST_SPEED_MM_S
        phi = np.where(moving, np.arctan2(d[:, 1], d[:, 0]), np.nan)
        start = self.count % self.capacity
        idx: slice | np.ndarray = slice(start, start + len(pos_mm))  # as a slice unless it
        if start + len(pos_mm) > self.capacity:  # wraps round the ring's end
            idx = np.arange(self.count, self.count + len(pos_mm)) % self.capacity
        self.pos_mm[idx], self.feed_mm_s[idx], self.line[idx], self.phi_rad[idx] = (
            pos_mm, feed_mm_s, line, phi)
        if cmd_counts is not None:
            self.cmd_counts[idx] = cmd_counts
        self.count += len(pos_mm)

    def counts_copy(self, first: int, n: int) -> np.ndarray:
        """A copy of the step counters of frames first.. first + n - 1 (a slice's unless they
        wrap round the ring's end)."""
        start = first % self.capacity
        if start + n <= self.capacity:
            return self.cmd_counts[start : start + n].copy()
        return self.cmd_counts[np.arange(first, first + n) % self.capacity]

    def at(self, seq: np.ndarray) -> slice | np.ndarray:
        """The ring's slots of frames seq (strictly increasing, as feedback rows are): a slice
        where they are consecutive and do not wrap (a block's rows: views, not gathers), else
        the index array."""
        n = len(seq)
        start = int(seq[0]) % self.capacity
        if int(seq[-1]) - int(seq[0]) == n - 1 and start + n <= self.capacity:
            return slice(start, start + n)
        return seq % self.capacity


@dataclass(frozen=True)
class FerrorTrip:
    axis: str
    ferror_mm: float
    limit_mm: float
    seq: int


class FerrorCheck:
    """ferror = commanded - encoder - lead per axis and frame; limit max(MIN_FERROR, FERROR
    |v|/Vmax).

    With servo pre-compensation a frame leads the path by the loop's lag on purpose; that lead
    (the frame sent less the path's reference for it, RefHistory) is not an error. LinuxCNC's
    following error with feed-forward is likewise the trajectory's minus the feedback. Without
    pre-compensation the lead is the rounding to pulses. The card's own commanded position and
    encoder come from one instant, so a card that numbers its rows a frame or two off shifts
    only the slowly varying lead."""

    def __init__(self, config: MachineConfig, start_counts: np.ndarray) -> None:
        self.names = config.axis_names
        self.pulse_mm = np.array([a.pulse_mm for a in config.axes])
        self.ferror_mm = np.array([a.ferror_mm for a in config.axes])
        self.min_ferror_mm = np.array([a.min_ferror_mm for a in config.axes])
        self.vmax_mm_s = np.array([a.max_velocity_mm_s for a in config.axes])
        self.period_s = config.sample_period_s
        self.last_cmd = np.asarray(start_counts, dtype=np.int64).copy()
        self.max_abs_mm = 0.0
        self.last_mm = np.zeros(len(self.names))

    def limits_mm(self, v_mm_s: np.ndarray) -> np.ndarray:
        """Vectorised AxisConfig.ferror_limit_mm over rows of per-axis velocities."""
        return np.maximum(self.min_ferror_mm, self.ferror_mm * np.abs(v_mm_s) / self.vmax_mm_s)

    def check(self, fb: Feedback, hist: RefHistory | None = None) -> FerrorTrip | None:
        """Rows of feedback; hist (the frames sent and their wanted rows) takes the lead out."""
        if not len(fb):
            return None
        cmd = fb.commanded_counts
        # On a cycle's rows the calls cost more than the work: slices rather than np.diff of a
        # np.vstack, and counts made float before they meet mm (the same values: a mixed
        # int * float ufunc casts them so, only slower).
        prev = np.concatenate((self.last_cmd[None, :], cmd[:-1]))
        v = (cmd - prev).astype(float) * self.pulse_mm / self.period_s
        self.last_cmd = cmd[-1].copy()
        ferr = (cmd - fb.encoder_counts).astype(float) * self.pulse_mm
        if hist is not None and hist.count:
            idx = hist.at(fb.seq)
            ferr = ferr - (hist.cmd_counts[idx].astype(float) * self.pulse_mm - hist.pos_mm[idx])
        self.last_mm = ferr[-1].copy()
        abs_mm = np.abs(ferr)
        self.max_abs_mm = max(self.max_abs_mm, float(abs_mm.max()))
        over = abs_mm > self.limits_mm(v)
        if not over.any():
            return None
        row, axis = np.argwhere(over)[0]
        return FerrorTrip(self.names[axis], float(ferr[row, axis]),
                          float(self.limits_mm(v)[row, axis]), int(fb.seq[row]))


NEAR_FRAMES = 40  # reference frames searched each side of a frame for the nearest path point
# Encoder rows measured together: one cycle brings 2, and 15 numpy calls on 2 rows were a
# quarter of the motion process's CPU. The frames they are measured against stay in the
# history ring (2 FIFOs + 1024 frames), far more than the BATCH_ROWS + NEAR_FRAMES frames a
# batch reaches back.
BATCH_ROWS = 128
# In virtual time (a block of 64 frames a cycle, nothing waits on the clock) a batch is larger:
# each costs a dozen numpy calls whatever its rows, and no cycle has a deadline to keep.
VIRTUAL_BATCH_ROWS = 512


class ContourStats:
    """The tool's measured distance from the path: encoder positions against the polyline of
    reference frames near their own frame (the sent path, stops and their overshoot included,
    not only eq. 28's normal component); running max/RMS/mean, BATCH_ROWS rows at a time."""

    def __init__(self, pulse_mm: np.ndarray, batch_rows: int | None = None) -> None:
        self.pulse_mm = pulse_mm
        self.batch_rows = batch_rows  # None: BATCH_ROWS
        self.max_abs_mm = 0.0
        self.sum_abs_mm = 0.0
        self.sum_sq_mm2 = 0.0
        self.n = 0
        self._seq: list[np.ndarray] = []
        self._counts: list[np.ndarray] = []
        self._rows = 0
        self._hist: RefHistory | None = None

    def update(self, fb: Feedback, hist: RefHistory) -> None:
        if len(fb):
            self.update_at(fb.seq, fb.encoder_counts, hist)

    def update_at(self, seq: np.ndarray, encoder_counts: np.ndarray, hist: RefHistory) -> None:
        """Encoder rows measured at (or, settling, after) frames seq."""
        if not hist.count:
            return
        self._hist = hist
        self._seq.append(np.asarray(seq))
        self._counts.append(np.atleast_2d(encoder_counts))
        self._rows += len(self._seq[-1])
        if self._rows >= (self.batch_rows or BATCH_ROWS):
            self._measure()

    def _measure(self) -> None:
        hist = self._hist
        if not self._rows or hist is None:
            return
        seq, counts = np.concatenate(self._seq), np.concatenate(self._counts)
        self._seq, self._counts, self._rows = [], [], 0
        eps = polyline_distance(counts * self.pulse_mm, *_windows(hist, seq))
        if eps.size:
            self.max_abs_mm = max(self.max_abs_mm, float(eps.max()))
            self.sum_abs_mm += float(eps.sum())
            self.sum_sq_mm2 += float(np.square(eps).sum())
            self.n += int(eps.size)

    def summary_um(self) -> dict[str, float]:
        self._measure()  # the rows since the last batch
        n = max(1, self.n)
        return {"max": self.max_abs_mm * 1e3, "rms": float(np.sqrt(self.sum_sq_mm2 / n)) * 1e3,
                "mean": self.sum_abs_mm / n * 1e3}


def _windows(hist: RefHistory, seq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference polyline of NEAR_FRAMES frames each side of each frame seq (clipped to
    the frames kept: the end frame repeated), axis first (D, R, W), and its segments' lengths
    (R, W - 1). The windows of a batch overlap: the frames they span are gathered and measured
    once, and consecutive rows (a block's) take their windows as views of them."""
    lo, hi = max(0, hist.count - hist.capacity), hist.count - 1
    first = int(seq.min()) - NEAR_FRAMES
    span = np.clip(np.arange(first, int(seq.max()) + NEAR_FRAMES + 1), lo, hi)
    verts = np.ascontiguousarray(hist.pos_mm[span % hist.capacity].T)
    lens = np.sqrt(np.square(np.diff(verts, axis=1)).sum(axis=0))  # 0 where clipped
    width = 2 * NEAR_FRAMES + 1
    if seq[-1] - seq[0] == len(seq) - 1 == len(span) - width:  # consecutive frames
        return _sliding(verts, width), _sliding(lens[None, :], width - 1)[0]
    at = (seq - (first + NEAR_FRAMES))[:, None] + np.arange(width)
    return verts[:, at], lens[at[:, :-1]]


def _sliding(a: np.ndarray, width: int) -> np.ndarray:
    """sliding_window_view(a, width, axis=1) of a C-contiguous 2-D array: the same read-only
    view, made directly (numpy's checks and wrappers cost more than the batch's windows)."""
    rows = a.shape[1] - width + 1
    step = a.strides[1]
    view = np.ndarray((a.shape[0], rows, width), a.dtype, a, 0, (a.strides[0], step, step))
    view.flags.writeable = False
    return view


def start_gap(first_mm: np.ndarray, start_counts: np.ndarray, pulse_mm: np.ndarray,
              first_step_mm: float = 0.0) -> str | None:
    """Why a program's first reference point cannot start here (more than a pulse and the
    first period's step from where the machine stands: a jump at start), or None. The first
    point is the one at t = T: from rest at Amax it is up to Amax T^2 / 2 on (1.2 um at 2450
    mm/s^2 and 1 ms; a quintic's start is gentler, a constant acceleration's is not)."""
    here_mm = start_counts * pulse_mm
    if np.all(np.abs(first_mm - here_mm) <= pulse_mm + first_step_mm):
        return None
    return (f"reference starts at {first_mm.tolist()} mm but the machine is at "
            f"{here_mm.tolist()} mm")
