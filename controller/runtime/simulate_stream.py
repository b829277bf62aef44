"""The servo model of `cncctl simulate`, streaming: reference chunks in, finished samples out.

Every per-sample figure of the whole-program simulation is computed here in bounded memory,
and bit for bit as the whole arrays would give it:
- the axis filters run in blocks of servo.BLOCK samples counted from the first one (the
  block-recursive filter rounds per block: another split would round differently);
- the path tangent of a sample needs the next reference point (central differences);
- the true distance of a sample needs the reference polyline up to NEAR_SAMPLES after it.
A sample is finished once all three are known; only the samples not yet finished and the
NEAR_SAMPLES before them are kept."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from controller.servo.model import BLOCK, contour_error_mm, filter_block
from controller.servo.prediction import SETTLE_S, axis_servos
from controller.servo.true_distance import (
    NEAR_SAMPLES,
    own_bound_mm,
    padded_columns,
    padded_window_distance_mm,
    segment_columns,
)

MOVING_MM = 1e-9  # a central difference shorter than this: the tangent is held


@dataclass(frozen=True, eq=False, repr=False)
class SampleBlock:
    """Finished samples i0 .. i0 + len - 1 of the run and the settling after it (the end point
    held for SETTLE_S); the first n_ref of them are reference samples."""

    i0: int
    n_ref: int
    ref_mm: np.ndarray  # (m, n_axes): the held end point in the settling
    feed_mm_s: np.ndarray
    line: np.ndarray
    ex_mm: np.ndarray
    ey_mm: np.ndarray
    contour_mm: np.ndarray  # eq. 28
    contouring: np.ndarray  # False on rapids (and the settling after a rapid)
    true_mm: np.ndarray  # the modelled tool's distance from the reference polyline

    def __len__(self) -> int:
        return len(self.ex_mm)


class ServoStream:
    """Push reference chunks (push), then finish(); each yields the samples finished so far."""

    def __init__(self, config: MachineConfig) -> None:
        self.T = config.sample_period_s  # noqa: N815
        self.settle = int(round(SETTLE_S / self.T))
        self.servos = axis_servos(config)
        self.states = [np.zeros(s.order) for s in self.servos]
        n_axes = len(config.axis_names)
        self.last_pos = np.zeros((1, n_axes))  # the position before the next sample (X0 Y0)
        self.base = 0  # global index of the first kept row
        self.done = 0  # samples before this are finished and gone
        self.filtered = 0  # tracking errors known before this
        self.n_ref = 0  # reference samples pushed
        self.rows = np.zeros((0, n_axes))  # reference rows from base (the settling appended)
        self.feed = np.zeros(0)
        self.line = np.zeros(0, np.int32)
        self.rapid = np.zeros(0, bool)
        self.phi = np.zeros(0)  # exact tangent where the generator knows it
        self.exact = np.zeros(0, bool)
        self.v = np.zeros((0, n_axes))  # velocities not yet filtered (from `filtered`)
        self.err = np.zeros((0, 2))  # tracking errors from base
        self.held_phi: float | None = None  # raw tangent of the last moving sample
        self.last_ref_phi = 0.0  # tangent of the last reference sample (the settling's)

    def push(self, pos_mm: np.ndarray, feed_mm_s: np.ndarray, line: np.ndarray, rapid: bool,
             phi_rad: np.ndarray | None) -> Iterator[SampleBlock]:
        n = len(pos_mm)
        if n == 0:
            return
        self._append(pos_mm, feed_mm_s, line, np.full(n, rapid),
                     np.zeros(n) if phi_rad is None else phi_rad, phi_rad is not None)
        self.n_ref += n
        yield from self._advance(final=False)

    def finish(self) -> Iterator[SampleBlock]:
        """The settling after the end (the last point held), then every sample left."""
        if self.n_ref == 0:
            return
        k = self.settle
        last = self.rows[-1:]
        self._append(np.repeat(last, k, axis=0), np.zeros(k), np.full(k, self.line[-1]),
                     np.full(k, self.rapid[-1]), np.zeros(k), False)
        yield from self._advance(final=True)

    def _append(self, pos: np.ndarray, feed: np.ndarray, line: np.ndarray, rapid: np.ndarray,
                phi: np.ndarray, exact: bool) -> None:
        full = np.vstack([self.last_pos, pos])
        self.v = np.vstack([self.v, np.diff(full, axis=0) / self.T])
        self.last_pos = pos[-1:]
        self.rows = np.vstack([self.rows, pos])
        self.feed = np.concatenate([self.feed, feed])
        self.line = np.concatenate([self.line, line.astype(np.int32)])
        self.rapid = np.concatenate([self.rapid, rapid])
        self.phi = np.concatenate([self.phi, phi])
        self.exact = np.concatenate([self.exact, np.full(len(pos), exact)])

    def _filter(self, final: bool) -> None:
        """Run the axis filters over whole blocks of BLOCK samples (all of them at the end)."""
        m = len(self.v) if final else len(self.v) // BLOCK * BLOCK
        if m == 0:
            return
        cols = []
        for axis, servo in enumerate(self.servos):  # a column, strided as the whole array's
            e, self.states[axis] = filter_block(servo, self.v[:m, axis], self.states[axis])
            cols.append(e)
        self.err = np.vstack([self.err, np.column_stack(cols)])
        self.v = self.v[m:]
        self.filtered += m

    def _advance(self, final: bool) -> Iterator[SampleBlock]:
        self._filter(final)
        total = self.base + len(self.rows)
        ready = total if final else min(self.filtered, total - NEAR_SAMPLES - 1)
        if ready <= self.done:
            return
        yield self._finish_samples(self.done, ready, total, final)
        self.done = ready
        self._forget(max(self.done - NEAR_SAMPLES - 1, self.base))

    def _forget(self, keep_from: int) -> None:
        cut = keep_from - self.base
        if cut <= 0:
            return
        for name in ("rows", "feed", "line", "rapid", "phi", "exact", "err"):
            setattr(self, name, getattr(self, name)[cut:])
        self.base = keep_from

    def _tangents(self, lo: int, hi: int, total: int, final: bool) -> np.ndarray:
        """Samples lo..hi-1 (relative to base): central differences, held where the path stops,
        then the generator's exact tangent where it has one (tangent_angles and the exact
        overrides of the whole-array form). The angle of a difference is taken only where it
        is read: at the samples without an exact tangent and for the one held."""
        d = self._differences(lo, hi, total, final)
        moving = np.hypot(d[:, 0], d[:, 1]) > MOVING_MM
        if self.held_phi is None:  # the very first sample: held until something moves
            self.held_phi = _angle(d, 0)
        phi = self.phi[lo:hi].copy()
        need = np.flatnonzero(~self.exact[lo:hi])
        if need.size:
            idx = np.where(moving, np.arange(len(d)), -1)
            np.maximum.accumulate(idx, out=idx)
            last = idx[need]
            at = np.maximum(last, 0)
            raw = np.arctan2(d[at, 1], d[at, 0])
            phi[need] = np.where(last >= 0, raw, self.held_phi)
        if moving.any():
            self.held_phi = _angle(d, int(np.flatnonzero(moving)[-1]))
        return phi

    def _differences(self, lo: int, hi: int, total: int, final: bool) -> np.ndarray:
        """Next minus previous reference point of samples lo..hi-1: the first sample's previous
        is itself, and at the end the last one's next is itself."""
        xy = self.rows[:, :2]
        end = total - 1 - self.base  # the last sample (at the end)
        if lo - 1 >= -self.base and (not final or hi <= end):
            return xy[lo + 1:hi + 1] - xy[lo - 1:hi - 1]
        i = np.arange(lo, hi)
        prev = xy[np.maximum(i - 1, -self.base)]
        nxt = xy[np.minimum(i + 1, end)] if final else xy[i + 1]
        return nxt - prev

    def _finish_samples(self, g0: int, g1: int, total: int, final: bool) -> SampleBlock:
        lo, hi = g0 - self.base, g1 - self.base
        err = self.err[lo:hi]
        ex, ey = np.ascontiguousarray(err[:, 0]), np.ascontiguousarray(err[:, 1])
        phi = self._tangents(lo, hi, total, final)
        n_ref = max(0, min(g1, self.n_ref) - g0)
        if g1 > self.n_ref:  # the settling keeps the tangent of the last reference sample
            last = self.last_ref_phi if n_ref == 0 else float(phi[n_ref - 1])
            phi[n_ref:] = last
        if n_ref:
            self.last_ref_phi = float(phi[n_ref - 1])
        held = self.rows[:, :2]
        act = held[lo:hi] - err
        true = self._true(held, act, lo, hi, total)
        return SampleBlock(g0, n_ref, self.rows[lo:hi], self.feed[lo:hi], self.line[lo:hi], ex,
                           ey, contour_error_mm(ex, ey, phi), ~self.rapid[lo:hi], true)

    def _true(self, held: np.ndarray, act: np.ndarray, lo: int, hi: int,
              total: int) -> np.ndarray:
        """distance_from_reference_mm (exact everywhere) of samples lo..hi-1 of the kept rows:
        the bound by their own two segments, then the windows where it is not zero. The terms
        of the segments both read are formed once (segments s0..s1, relative to base)."""
        i = np.arange(lo, hi)
        if total < 2:
            return np.hypot(*(act - held[lo:hi]).T)
        first, last = -self.base, total - 2 - self.base  # global segments 0 and total - 2
        s0, s1 = max(lo - NEAR_SAMPLES, first), min(hi + NEAR_SAMPLES - 2, last)
        cols = segment_columns(held[s0:s1 + 2])
        before, at = _own_segments(lo - s0, hi - s0, first - s0, last - s0)
        bound = own_bound_mm(cols, act, before, at)
        pos = np.flatnonzero(bound > 0.0)
        if pos.size == 0:
            return bound
        out = bound.copy()
        out[pos] = _windows(cols, s0, act, i, pos, self.base, total, bound[pos])
        return out


def _windows(cols: tuple[np.ndarray, ...], s0: int, act: np.ndarray, i: np.ndarray,
             pos: np.ndarray, base: int, total: int, upper_mm: np.ndarray) -> np.ndarray:
    """window_distance_mm for the samples i[pos] (rows relative to base) on the kept part of the
    polyline: its segments from the first window's start to the last one's end (cols holds
    the segments from s0 on). A window is clipped only at the polyline's true ends (global 0
    and total - 2), which are then the ends of that part too."""
    near = NEAR_SAMPLES
    lo_seg = max(int(i[pos[0]]) - near, -base)
    hi_seg = min(int(i[pos[-1]]) + near - 1, total - 2 - base)
    part = tuple(c[lo_seg - s0:hi_seg - s0 + 1] for c in cols)
    return padded_window_distance_mm(padded_columns(part, near), act[pos], i[pos] - lo_seg,
                                     near, upper_mm)


def _own_segments(lo: int, hi: int, first: int, last: int) -> tuple[np.ndarray | slice, ...]:
    """The segments before and at samples lo..hi-1, clipped to first..last: slices where no
    sample needs clipping (a view, not a gather), else indices."""
    if first <= lo - 1 and hi - 1 <= last:
        return slice(lo - 1, hi - 1), slice(lo, hi)
    i = np.arange(lo, hi)
    return np.clip(i - 1, first, last), np.clip(i, first, last)


def _angle(d: np.ndarray, j: int) -> float:
    """arctan2 of row j of the differences d (on an array, as for all rows at once)."""
    return float(np.arctan2(d[j:j + 1, 1], d[j:j + 1, 0])[0])
