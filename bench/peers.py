"""Peers bench: ours against ports of Klipper's look-ahead and grbl's planner, at equal true error.

Usage: python bench/peers.py [PROGRAM ...] [--tolerances-um 1 10] [--markdown]

Every planner's reference points (one per period T of the config) run through the same Table II
servo model (`tracking_error_mm` per axis on the per-sample velocity; actual = reference - error,
from rest, with SETTLE_S of held final reference after the end so the settling overshoot is seen).
Two contour errors are measured on those actual positions: eq. 28 (`contour_error_mm`, the normal
component of the axis errors at the reference point, tangent from central differences of the
reference; ours reports its own eq. 28 with the generator's exact tangent) and the TRUE error,
the distance of the actual position from the programmed path (NURBS and closing G1, as a polyline
within 0.02 um; `controller.servo.path_distance`). Each peer is fed the program's
NURBS flattened into G1 chords (chord error within 1 um and 10 um: every chord is checked at its
quarter, half and three-quarter points, as a CAM post would), and the program's G1 as is. Each
peer's acceleration is bisected (geometrically, to 0.5 %) for the largest value whose TRUE
contour error max is within what ours plans for: eps_max less sqrt(2) pulses of quantisation
margin (controller.servo.prediction.planning_limit_mm), since on a machine both
would need that margin; Vmax = the config's Vmax.
The time bound is bench/time_bound.py's (Amax, Vmax, chord tolerance, T of the config).

What was ported, from which upstream files and commits:

* Klipper, klippy/toolhead.py at Klipper3d/klipper commit ecccd21f2a6f5b0c07ea2c213bb9290a4de6bc2c
  (the file's last change in the snapshot 84104bbbd7625d28b4eaaad83f4562972460ecd9):
  `Move.__init__` (max_cruise_v2, delta_v2, mcr_delta_v2 with the minimum-cruise-ratio pseudo
  acceleration), `Move.calc_junction` (junction deviation from square_corner_velocity,
  jd = scv^2 (sqrt 2 - 1) / accel as in `_calc_junction_deviation`; the "approximated
  centripetal velocity" R_jd jd accel, and the mid-move contact limits delta_v2 tan(theta/2) / 4),
  `Move.set_junction` (the trapezoid), `LookAheadQueue.add_move` and `flush` line by line,
  including the lazy flush driven by the junction flush time (BUFFER_TIME_HIGH 1.0 s first,
  then LOOKAHEAD_FLUSH_TIME 0.150 s) and the final full flush at program end. Defaults:
  square_corner_velocity 5 mm/s, minimum_cruise_ratio 0.5 (this Klipper's replacement for
  max_accel_to_decel = accel / 2; the tuned Klipper keeps it), max_accel = Amax 2450.
* grbl 1.1, grbl/planner.c at gnea/grbl commit b75e5571eeaeb22a88304716fb1e7411f9c28be0 (snapshot
  bfb67f0c7963fe3ce4aaf8a97f9009ea5a8db36e): `plan_buffer_line` (per-axis limits through
  `limit_value_by_axis_maximum` of nuts_bolts.c for the block acceleration, the rapid rate and
  the junction acceleration; max_junction_speed_sqr from junction deviation 0.01 mm
  (defaults.h), the 0.999999 cosine cut-offs, MINIMUM_JUNCTION_SPEED 0; max_entry_speed_sqr of
  `plan_compute_profile_parameters`), `planner_recalculate` (reverse pass from a stop at the
  newest block, forward pass), and the block buffer of planner.h (BLOCK_BUFFER_SIZE 16, so 15
  blocks including the one the stepper is preparing). Per-axis acceleration = the bisected value,
  per-axis max rate = Vmax. The executing block's trapezoid (stepper.c `st_prep_buffer`: entry at
  the current speed, accelerate to nominal, cruise, decelerate to the planned exit) is cut into
  the stepper's segments of DT_SEGMENT = 10 ms (ACCELERATION_TICKS_PER_SECOND 100; a segment
  ends early at its block's end and never spans two blocks); each segment ends on the trapezoid
  and steps at a constant rate inside it, so the reference is linear in time between segment
  ends (`--grbl-ideal` samples the trapezoids themselves instead).

What was simplified, and why:

* Klipper is sampled on its exact trapezoids at T: its itersolve places steps on the exact trapq
  curve, so only the step quantisation (1 um) is left out, as it is for ours here.
* grbl streaming is modelled with a full buffer at all times (the sender is never behind): when
  block j starts being prepared, the buffer holds j..j+14 and the newest is planned to stop;
  block j's exit is fixed until it is finished. `planner_recalculate`'s block_buffer_planned
  pointer is an optimisation that does not change the plan, so both passes run over the buffer.
  Arithmetic is float64 (grbl's is float32, Klipper's is Python float).
* Klipper's step compression and input shaping, and grbl's step quantisation, AMASS and the
  step-time remainder carried between segments are not modelled: the reference points are
  positions at T, as ours are, not quantised to the 1 um pulse.
* `--grbl-buffer N` plans grbl over N blocks instead of 15 (what grbl's ARM descendants allow);
  the default is grbl 1.1's 15.
* The bisection assumes the true error grows with the acceleration near the limit; a scan of 25
  accelerations from 100 to 2450 mm/s^2 for both peers on the three programs and both
  tolerances showed exactly one crossing of 30 um in every case (the error is not monotonic
  away from it, e.g. grbl's plateaus).
* Observed, not a simplification: grbl's junction speed comes from a virtual circle of radius
  jd cos(phi/2) / (1 - cos(phi/2)), about 8 jd / phi^2 for a turn phi between chords; on 1 um
  chords (phi of a few hundredths of a radian) that is tens of mm where the curve's radius is
  under 1 mm at the airfoil's nose. Junctions barely slow grbl on these curves; what keeps it
  within 30 um once tuned is its 15-block buffer (every block must be able to stop by the
  buffer's end), hence its low tuned accelerations and long times at 1 um. With a bigger buffer
  (`--grbl-buffer 256`) it needs a lower acceleration still (58-65 mm/s^2 at 1 um).
* Our own ph-lookahead is whatever `simulate()` plans in the working tree at the time of the run.

Check of the Klipper port: `python bench/peers.py --verify-klipper TOOLHEAD_PY` runs the upstream
file's own Move and LookAheadQueue (e.g. `git show ecccd21f:klippy/toolhead.py`) on the same
chords and compares every move's phase times and speeds (they agree within 2e-11 on all three
programs at 2450, 900 and 300 mm/s^2).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))

from time_bound import arc_length_samples  # noqa: E402

from controller.blocks import LineBlock, NcBlock, NurbsBlock  # noqa: E402
from controller.config import MachineConfig, load_config  # noqa: E402
from controller.generator.feed.time_bound import time_optimal_bound_s  # noqa: E402
from controller.geometry.nurbs import Nurbs  # noqa: E402
from controller.interpreter.program import read_program  # noqa: E402
from controller.runtime.simulation import simulate, tangent_angles  # noqa: E402
from controller.servo.model import contour_error_mm, tracking_error_mm  # noqa: E402
from controller.servo.path_distance import (  # noqa: E402
    PathDistance,
    block_polyline,
    path_polyline,
    sample_curve,
)
from controller.servo.precompensation import Precompensator  # noqa: E402
from controller.servo.prediction import (  # noqa: E402
    planning_limit_mm,
    plant_servos,
)

PROGRAMS = ("nc_programs/naca2415.nc", "nc_programs/naca2415_loop.nc", "nc_programs/butterfly.nc")
SETTLE_S = 0.3  # held final reference after the end: the Table II servo settles within ~50 ms
KLIPPER_SCV_MM_S = 5.0  # square_corner_velocity default
KLIPPER_MCR = 0.5  # minimum_cruise_ratio default
KLIPPER_BUFFER_TIME_HIGH_S = 1.0
KLIPPER_LOOKAHEAD_FLUSH_TIME_S = 0.150
GRBL_JUNCTION_DEVIATION_MM = 0.01
GRBL_BLOCK_BUFFER_SIZE = 16  # planner.h; the ring keeps one slot empty: 15 blocks planned
GRBL_DT_SEGMENT_S = 1.0 / 100  # stepper.c DT_SEGMENT: 1 / ACCELERATION_TICKS_PER_SECOND


@dataclass(frozen=True)
class Moves:
    """Planned straight moves: start points, unit directions, and trapezoid phases (s, mm/s)."""

    start_mm: np.ndarray  # (n, 2)
    dir: np.ndarray  # (n, 2)
    accel_t: np.ndarray
    cruise_t: np.ndarray
    decel_t: np.ndarray
    start_v: np.ndarray
    cruise_v: np.ndarray
    accel_mm_s2: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(np.sum(self.accel_t + self.cruise_t + self.decel_t))


# ---------------------------------------------------------------- Klipper (klippy/toolhead.py)

class KlipperMove:
    """toolhead.py's Move, for a 2-axis kinematic move (no extruder)."""

    __slots__ = ("start_pos", "axes_r", "move_d", "accel", "junction_deviation",
                 "min_move_t", "max_start_v2", "max_cruise_v2", "delta_v2", "next_junction_v2",
                 "max_mcr_start_v2", "mcr_delta_v2", "start_v", "cruise_v", "end_v", "accel_t",
                 "cruise_t", "decel_t")

    def __init__(self, th: KlipperToolhead, start: np.ndarray, end: np.ndarray,
                 speed: float) -> None:
        self.start_pos = start
        self.accel = th.max_accel
        self.junction_deviation = th.junction_deviation
        velocity = min(speed, th.max_velocity)
        d = end - start
        self.move_d = move_d = math.hypot(d[0], d[1])
        self.axes_r = (d[0] / move_d, d[1] / move_d)
        self.min_move_t = move_d / velocity
        self.max_start_v2 = 0.0
        self.max_cruise_v2 = velocity**2
        self.delta_v2 = 2.0 * move_d * self.accel
        self.next_junction_v2 = 999999999.9
        self.max_mcr_start_v2 = 0.0
        self.mcr_delta_v2 = 2.0 * move_d * th.mcr_pseudo_accel

    def calc_junction(self, prev: KlipperMove) -> None:
        max_start_v2 = min(self.max_cruise_v2, prev.max_cruise_v2, prev.next_junction_v2,
                           prev.max_start_v2 + prev.delta_v2)
        junction_cos_theta = -(self.axes_r[0] * prev.axes_r[0] + self.axes_r[1] * prev.axes_r[1])
        sin_theta_d2 = math.sqrt(max(0.5 * (1.0 - junction_cos_theta), 0.0))
        cos_theta_d2 = math.sqrt(max(0.5 * (1.0 + junction_cos_theta), 0.0))
        one_minus_sin_theta_d2 = 1.0 - sin_theta_d2
        if one_minus_sin_theta_d2 > 0.0 and cos_theta_d2 > 0.0:
            r_jd = sin_theta_d2 / one_minus_sin_theta_d2
            move_jd_v2 = r_jd * self.junction_deviation * self.accel
            pmove_jd_v2 = r_jd * prev.junction_deviation * prev.accel
            quarter_tan_theta_d2 = 0.25 * sin_theta_d2 / cos_theta_d2
            move_centripetal_v2 = self.delta_v2 * quarter_tan_theta_d2
            pmove_centripetal_v2 = prev.delta_v2 * quarter_tan_theta_d2
            max_start_v2 = min(max_start_v2, move_jd_v2, pmove_jd_v2, move_centripetal_v2,
                               pmove_centripetal_v2)
        self.max_start_v2 = max_start_v2
        self.max_mcr_start_v2 = min(max_start_v2, prev.max_mcr_start_v2 + prev.mcr_delta_v2)

    def set_junction(self, start_v2: float, cruise_v2: float, end_v2: float) -> None:
        half_inv_accel = 0.5 / self.accel
        accel_d = (cruise_v2 - start_v2) * half_inv_accel
        decel_d = (cruise_v2 - end_v2) * half_inv_accel
        cruise_d = self.move_d - accel_d - decel_d
        self.start_v = start_v = math.sqrt(start_v2)
        self.cruise_v = cruise_v = math.sqrt(cruise_v2)
        self.end_v = end_v = math.sqrt(end_v2)
        self.accel_t = accel_d / ((start_v + cruise_v) * 0.5)
        self.cruise_t = cruise_d / cruise_v
        self.decel_t = decel_d / ((end_v + cruise_v) * 0.5)


class KlipperToolhead:
    """The parts of ToolHead that planning uses, and LookAheadQueue."""

    def __init__(self, max_velocity: float, max_accel: float, scv: float = KLIPPER_SCV_MM_S,
                 min_cruise_ratio: float = KLIPPER_MCR) -> None:
        self.max_velocity, self.max_accel = max_velocity, max_accel
        self.junction_deviation = scv**2 * (math.sqrt(2.0) - 1.0) / max_accel
        self.mcr_pseudo_accel = max_accel * (1.0 - min_cruise_ratio)
        self.queue: list[KlipperMove] = []
        self.junction_flush = KLIPPER_BUFFER_TIME_HIGH_S
        self.done: list[KlipperMove] = []

    def add_move(self, move: KlipperMove) -> None:
        self.queue.append(move)
        if len(self.queue) == 1:
            return
        move.calc_junction(self.queue[-2])
        self.junction_flush -= move.min_move_t
        if self.junction_flush <= 0.0:
            self.done.extend(self.flush(lazy=True))

    def flush(self, lazy: bool = False) -> list[KlipperMove]:
        self.junction_flush = KLIPPER_LOOKAHEAD_FLUSH_TIME_S
        update_flush_count = lazy
        queue = self.queue
        flush_count = len(queue)
        junction_info: list[tuple] = [()] * flush_count
        next_start_v2 = next_mcr_start_v2 = peak_cruise_v2 = 0.0
        pending_cv2_assign = 0
        for i in range(flush_count - 1, -1, -1):
            move = queue[i]
            reachable_start_v2 = next_start_v2 + move.delta_v2
            start_v2 = min(move.max_start_v2, reachable_start_v2)
            cruise_v2 = None
            pending_cv2_assign += 1
            reach_mcr_start_v2 = next_mcr_start_v2 + move.mcr_delta_v2
            mcr_start_v2 = min(move.max_mcr_start_v2, reach_mcr_start_v2)
            if mcr_start_v2 < reach_mcr_start_v2:
                if (mcr_start_v2 + move.mcr_delta_v2 > next_mcr_start_v2
                        or pending_cv2_assign > 1):
                    if update_flush_count and peak_cruise_v2:
                        flush_count = i + pending_cv2_assign
                        update_flush_count = False
                    peak_cruise_v2 = (mcr_start_v2 + reach_mcr_start_v2) * 0.5
                cruise_v2 = min((start_v2 + reachable_start_v2) * 0.5, move.max_cruise_v2,
                                peak_cruise_v2)
                pending_cv2_assign = 0
            junction_info[i] = (move, start_v2, cruise_v2, next_start_v2)
            next_start_v2 = start_v2
            next_mcr_start_v2 = mcr_start_v2
        if update_flush_count or not flush_count:
            return []
        prev_cruise_v2 = 0.0
        for i in range(flush_count):
            move, start_v2, cruise_v2, next_start_v2 = junction_info[i]
            if cruise_v2 is None:
                cruise_v2 = min(prev_cruise_v2, start_v2)
            move.set_junction(min(start_v2, cruise_v2), cruise_v2, min(next_start_v2, cruise_v2))
            prev_cruise_v2 = cruise_v2
        res = queue[:flush_count]
        del queue[:flush_count]
        return res


def klipper_plan(points_mm: np.ndarray, feed_mm_s: float, max_velocity: float,
                 max_accel: float, min_cruise_ratio: float = KLIPPER_MCR) -> Moves:
    """G1 moves through the points (from rest to rest) planned by Klipper's look-ahead."""
    th = KlipperToolhead(max_velocity, max_accel, min_cruise_ratio=min_cruise_ratio)
    for a, b in zip(points_mm[:-1], points_mm[1:], strict=True):
        th.add_move(KlipperMove(th, a, b, feed_mm_s))
    th.done.extend(th.flush())
    ms = th.done
    return Moves(np.array([m.start_pos for m in ms]), np.array([m.axes_r for m in ms]),
                 *(np.array([getattr(m, k) for m in ms])
                   for k in ("accel_t", "cruise_t", "decel_t", "start_v", "cruise_v", "accel")))


# ---------------------------------------------------------------- grbl (grbl/planner.c)

def _limit_by_axis(max_value: float, unit: np.ndarray) -> np.ndarray:
    """nuts_bolts.c limit_value_by_axis_maximum, the same maximum on every axis, row-wise."""
    a = np.abs(unit)
    return max_value / np.where(a > 0, a, 0.0).max(axis=1)


def grbl_plan(points_mm: np.ndarray, feed_mm_s: float, max_rate: float, accel: float,
              junction_deviation: float = GRBL_JUNCTION_DEVIATION_MM,
              buffer_blocks: int = GRBL_BLOCK_BUFFER_SIZE - 1) -> Moves:
    """G1 moves through the points planned by grbl's planner over its block buffer."""
    delta = np.diff(points_mm, axis=0)
    mm = np.hypot(delta[:, 0], delta[:, 1])
    unit = delta / mm[:, None]
    acc = _limit_by_axis(accel, unit)
    nominal = np.minimum(feed_mm_s, _limit_by_axis(max_rate, unit))
    n = len(mm)
    max_junction_sqr = np.zeros(n)
    if n > 1:
        cos_t = -np.einsum("ij,ij->i", unit[:-1], unit[1:])
        ju = unit[1:] - unit[:-1]
        jn = np.hypot(ju[:, 0], ju[:, 1])
        ju = ju / np.where(jn > 0, jn, 1.0)[:, None]
        j_acc = _limit_by_axis(accel, np.where(jn[:, None] > 0, ju, 1.0))
        sin_d2 = np.sqrt(np.clip(0.5 * (1.0 - cos_t), 0.0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            jv2 = np.maximum(0.0, j_acc * junction_deviation * sin_d2 / (1.0 - sin_d2))
        jv2 = np.where(cos_t < -0.999999, 1e38, jv2)  # SOME_LARGE_VALUE: straight on
        max_junction_sqr[1:] = np.where(cos_t > 0.999999, 0.0, jv2)  # reversal: stop
    prev_nominal = np.r_[1e38, nominal[:-1]]
    max_entry_sqr = np.minimum(np.minimum(prev_nominal, nominal) ** 2, max_junction_sqr)
    two_a_mm = (2.0 * acc * mm).tolist()
    max_entry = max_entry_sqr.tolist()
    entry_v2 = np.zeros(n)
    exit_v2 = np.zeros(n)
    v2 = 0.0  # speed^2 at which the executing block starts
    for j in range(n):
        hi = min(j + buffer_blocks, n)
        # Reverse pass: the newest block in the buffer ends at rest.
        nxt = 0.0
        for k in range(hi - 1, j, -1):
            nxt = min(max_entry[k], nxt + two_a_mm[k])
        # Forward pass, as far as the executing block's exit.
        out = min(nxt, v2 + two_a_mm[j]) if j + 1 < n else 0.0
        entry_v2[j], exit_v2[j] = v2, out
        v2 = out
    return _trapezoids(points_mm[:-1], unit, mm, acc, nominal, entry_v2, exit_v2)


def _trapezoids(start: np.ndarray, unit: np.ndarray, mm: np.ndarray, acc: np.ndarray,
                nominal: np.ndarray, v0_2: np.ndarray, v1_2: np.ndarray) -> Moves:
    """Accelerate from v0 to nominal, cruise, decelerate to v1 (a triangle when short)."""
    vc2 = np.minimum(nominal**2, 0.5 * (2.0 * acc * mm + v0_2 + v1_2))
    vc2 = np.maximum(vc2, np.maximum(v0_2, v1_2))
    accel_d = (vc2 - v0_2) / (2.0 * acc)
    decel_d = (vc2 - v1_2) / (2.0 * acc)
    cruise_d = np.maximum(mm - accel_d - decel_d, 0.0)
    v0, vc, v1 = np.sqrt(v0_2), np.sqrt(vc2), np.sqrt(v1_2)
    return Moves(start, unit, accel_d / (0.5 * (v0 + vc)), cruise_d / vc,
                 decel_d / (0.5 * (v1 + vc)), v0, vc, acc)


# ---------------------------------------------------------------- sampling and measurement

def positions_at(moves: Moves, t_s: np.ndarray) -> np.ndarray:
    """Positions (N, 2) on the planned trapezoids at times t (clipped to the motion)."""
    dur = moves.accel_t + moves.cruise_t + moves.decel_t
    t_end = np.cumsum(dur)
    t = np.clip(t_s, 0.0, t_end[-1])
    i = np.minimum(np.searchsorted(t_end, t, side="left"), len(dur) - 1)
    tau = t - (t_end[i] - dur[i])
    ta, tc, a = moves.accel_t[i], moves.cruise_t[i], moves.accel_mm_s2[i]
    v0, vc = moves.start_v[i], moves.cruise_v[i]
    t1 = np.clip(tau, 0.0, ta)
    d = v0 * t1 + 0.5 * a * t1 * t1
    t2 = np.clip(tau - ta, 0.0, tc)
    d += vc * t2
    t3 = np.clip(tau - ta - tc, 0.0, moves.decel_t[i])
    d += vc * t3 - 0.5 * a * t3 * t3
    return moves.start_mm[i] + d[:, None] * moves.dir[i]


def sample_times(moves: Moves, period_s: float) -> np.ndarray:
    """t = T, 2T, ... up to the first sample at or after the end of the last move."""
    n = int(math.ceil(moves.duration_s / period_s - 1e-9))
    return np.arange(1, n + 1) * period_s


def sample_moves(moves: Moves, period_s: float) -> np.ndarray:
    """Reference positions at T, 2T, ... on the exact trapezoids (Klipper's trapq)."""
    return positions_at(moves, sample_times(moves, period_s))


def sample_grbl_segments(moves: Moves, period_s: float,
                         segment_s: float = GRBL_DT_SEGMENT_S) -> np.ndarray:
    """Reference positions at T, 2T, ... as grbl's stepper moves: st_prep_buffer cuts each block
    into segments of DT_SEGMENT (the last one cut short at the block's end; segments never span
    blocks), ends each segment on the exact trapezoid and steps at a constant rate inside it, so
    the position is linear in time between segment ends."""
    dur = moves.accel_t + moves.cruise_t + moves.decel_t
    t0 = np.cumsum(dur) - dur
    n_seg = np.maximum(np.ceil(dur / segment_s - 1e-9).astype(np.int64), 1)
    first = np.repeat(np.cumsum(n_seg) - n_seg, n_seg)
    k = np.arange(int(n_seg.sum())) - first + 1
    blk = np.repeat(np.arange(len(dur)), n_seg)
    t_knots = np.r_[0.0, np.minimum(t0[blk] + k * segment_s, t0[blk] + dur[blk])]
    p_knots = positions_at(moves, t_knots)
    t = sample_times(moves, period_s)
    return np.column_stack([np.interp(t, t_knots, p_knots[:, 0]),
                            np.interp(t, t_knots, p_knots[:, 1])])


@dataclass(frozen=True)
class Measured:
    motion_s: float
    true_max_um: float
    eq28_max_um: float
    true_at_mm: tuple[float, float]
    true_at_s: float  # time of the true max (after motion_s: in the settling)


def compensated(ref_mm: np.ndarray, start_mm: np.ndarray, config: MachineConfig) -> np.ndarray:
    """The frames the motion loop sends for a wanted reference with servo_precompensation: led
    by the model's lag, then the settling of that lead at the end point."""
    pc = Precompensator([a.servo for a in config.axes[:2]], config.sample_period_s, start_mm[:2])
    return pc.to_rest(ref_mm[:, :2])


def run_servo(frames_mm: np.ndarray, start_mm: np.ndarray, config: MachineConfig
              ) -> tuple[np.ndarray, np.ndarray]:
    """Actual positions of the plant (Table II loops, config's servo) driven by these frames
    from rest at start_mm, with SETTLE_S of the last frame held after them; and the held
    frames."""
    T = config.sample_period_s  # noqa: N806
    settle = int(round(SETTLE_S / T))
    pos = np.vstack([start_mm[None, :2], frames_mm[:, :2],
                     np.repeat(frames_mm[-1:, :2], settle, 0)])
    v = np.diff(pos, axis=0) / T
    sx, sy = plant_servos(config)
    e = np.column_stack([tracking_error_mm(sx, v[:, 0]), tracking_error_mm(sy, v[:, 1])])
    return pos[1:] - e, pos[1:]


def measure(ref_mm: np.ndarray, start_mm: np.ndarray, motion_s: float, path: PathDistance,
            config: MachineConfig, eq28_mm: np.ndarray | None = None,
            frames_mm: np.ndarray | None = None) -> Measured:
    """The true error of the plant driven by frames_mm (default: the reference itself), and
    eq. 28 of the wanted reference against that actual position."""
    frames = ref_mm[:, :2] if frames_mm is None else frames_mm
    act, _ = run_servo(frames, start_mm, config)
    fp = path.measure(act)
    k = int(np.argmax(fp.distance_mm))
    if eq28_mm is None:
        wanted = np.vstack([ref_mm[:, :2], np.repeat(ref_mm[-1:, :2], len(act) - len(ref_mm), 0)])
        e = wanted - act
        eq28_mm = contour_error_mm(e[:, 0], e[:, 1], tangent_angles(wanted))
    return Measured(motion_s, float(fp.distance_mm[k] * 1e3), float(np.abs(eq28_mm).max() * 1e3),
                    (float(act[k, 0]), float(act[k, 1])), (k + 1) * config.sample_period_s)


def flatten(blocks: list[NcBlock], tol_mm: float) -> np.ndarray:
    """The motion blocks as G1 chord end points: NURBS within tol_mm, lines as they are."""
    parts: list[np.ndarray] = []
    for b in blocks:
        if isinstance(b, NurbsBlock):
            c = Nurbs.from_block(b)

            def ev(u: np.ndarray, c: Nurbs = c) -> np.ndarray:
                return c.evaluate(np.clip(u, c.u_start, c.u_end), order=0)[0]

            pts = ev(sample_curve(ev, c.u_start, c.u_end, tol_mm))
        elif isinstance(b, LineBlock):
            pts = block_polyline(b)
        else:
            continue
        if parts:
            pts = pts[1:]
        parts.append(pts)
    pts = np.vstack(parts)
    keep = np.r_[True, np.hypot(*np.diff(pts, axis=0).T) > 1e-9]
    return pts[keep]


def tune(evaluate: Callable[[float], Measured], limit_um: float, a_max: float,
         a_min: float = 20.0) -> tuple[float, Measured | None]:
    """Largest acceleration (geometric bisection to 0.5 %) whose true error is within limit."""
    top = evaluate(a_max)
    if top.true_max_um <= limit_um:
        return a_max, top
    lo, hi = a_min, a_max
    best = evaluate(lo)
    if best.true_max_um > limit_um:
        return lo, None
    while hi / lo > 1.005:
        mid = math.sqrt(lo * hi)
        m = evaluate(mid)
        if m.true_max_um <= limit_um:
            lo, best = mid, m
        else:
            hi = mid
    return lo, best


def bound_s(program: str, config: MachineConfig) -> float:
    ip = config.interpolator
    s, kappa = arc_length_samples(Path(program))
    return time_optimal_bound_s(s, kappa, ip.max_feed_mm_s, ip.max_accel_mm_s2,
                                config.sample_period_s, ip.chord_tolerance_mm)


@dataclass(frozen=True)
class Row:
    name: str
    chord_um: float | None
    accel_mm_s2: float | None
    m: Measured | None


def bench_program(program: str, config: MachineConfig, tolerances_um: list[float],
                  log: Callable[[str], None], grbl_segments: bool = True,
                  grbl_buffer: int = GRBL_BLOCK_BUFFER_SIZE - 1, ablation: bool = True
                  ) -> tuple[list[Row], float]:
    """Ours (as configured, and the paper's method without pre-compensation), then Klipper and
    grbl at their default and tuned accelerations per tolerance; with ablation, each peer also
    tuned with our servo pre-compensation on its reference (what the feed-forward alone buys)."""
    ip = config.interpolator
    # Equal accuracy: each peer is tuned to the error ours plans for, eps_max less the margin
    # that pulse and encoder quantisation take on a machine (ours and theirs alike).
    limit_um = planning_limit_mm(config) * 1e3
    vmax, amax = ip.max_feed_mm_s, ip.max_accel_mm_s2
    blocks = list(read_program(program, config))
    path = PathDistance(path_polyline(blocks))
    origin = np.zeros(2)
    # simulate() starts the servo at X0 Y0 at rest, as run_servo does (the programs start there).
    rows = []
    for name, cfg in ours_variants(config):
        traj = simulate(blocks, cfg, "ph-lookahead")
        frames = (compensated(traj.ref_mm, origin, cfg)
                  if cfg.interpolator.servo_precompensation else None)
        m = measure(traj.ref_mm[:, :2], origin, len(traj.t_s) * cfg.sample_period_s, path, cfg,
                    traj.contour_mm[traj.contouring], frames)
        rows.append(Row(name, None, amax, m))
        log(f"{Path(program).name}: {name} {m}")
    for tol_um in tolerances_um:
        pts = flatten(blocks, tol_um * 1e-3)
        start = pts[0]
        log(f"  chords at {tol_um} um: {len(pts) - 1} moves")

        def k_eval(a: float, pts: np.ndarray = pts, start: np.ndarray = start,
                   comp: bool = False) -> Measured:
            mv = klipper_plan(pts, vmax, vmax, a)
            ref = sample_moves(mv, config.sample_period_s)
            return measure(ref, start, mv.duration_s, path, config,
                           frames_mm=compensated(ref, start, config) if comp else None)

        def g_eval(a: float, pts: np.ndarray = pts, start: np.ndarray = start,
                   comp: bool = False) -> Measured:
            mv = grbl_plan(pts, vmax, vmax, a, buffer_blocks=grbl_buffer)
            sampler = sample_grbl_segments if grbl_segments else sample_moves
            ref = sampler(mv, config.sample_period_s)
            return measure(ref, start, mv.duration_s, path, config,
                           frames_mm=compensated(ref, start, config) if comp else None)

        for name, ev in (("Klipper", k_eval), ("grbl", g_eval)):
            default = ev(amax)
            rows.append(Row(f"{name} default", tol_um, amax, default))
            a_t, tuned = tune(ev, limit_um, amax)
            rows.append(Row(f"{name} tuned", tol_um, a_t if tuned else None, tuned))
            log(f"  {name}: default {default}; tuned A {a_t:.0f}: {tuned}")
            if ablation:
                a_c, comp = tune(partial(ev, comp=True), limit_um, amax)
                rows.append(Row(f"{name} + our pre-compensation, tuned", tol_um,
                                a_c if comp else None, comp))
                log(f"  {name} + pre-compensation: tuned A {a_c:.0f}: {comp}")
    return rows, bound_s(program, config)


def ours_variants(config: MachineConfig) -> list[tuple[str, MachineConfig]]:
    """Ours as configured first (the row the ratios are taken against), then with the paper's
    quintic transitions (ramp_share 1) where the config has others, then the paper's method
    (quintic, no pre-compensation)."""
    ip = config.interpolator

    def label(cfg: MachineConfig) -> str:
        c = cfg.interpolator
        if not c.servo_precompensation and c.ramp_share == 1.0:
            return "ours: ph-lookahead, paper (no pre-compensation)"
        comp = "pre-compensated" if c.servo_precompensation else "no pre-compensation"
        shape = "quintic" if c.ramp_share == 1.0 else f"ramp_share {c.ramp_share:g}"
        return f"ours: ph-lookahead, {comp}, {shape}"

    variants = [config]
    if ip.ramp_share != 1.0 and ip.servo_precompensation:
        variants.append(replace(config, interpolator=replace(ip, ramp_share=1.0)))
    paper = replace(config, interpolator=replace(ip, servo_precompensation=False, ramp_share=1.0))
    if paper.interpolator != ip:
        variants.append(paper)
    return [(label(cfg), cfg) for cfg in variants]


def table(program: str, rows: list[Row], bound: float, markdown: bool) -> str:
    ours = rows[0].m
    assert ours is not None
    head = ("planner", "chords (um)", "accel (mm/s^2)", "motion time (s)", "/ bound",
            "true max (um)", "at t (s)", "eq. 28 max (um)", "ours / this (time)")
    body = []
    for r in rows:
        m = r.m
        cells = [r.name, "-" if r.chord_um is None else f"{r.chord_um:g}",
                 "-" if r.accel_mm_s2 is None else f"{r.accel_mm_s2:.0f}"]
        if m is None:
            cells += ["no acceleration keeps the limit"] + [""] * 5
        else:
            cells += [f"{m.motion_s:.4f}", f"{m.motion_s / bound:.3f}", f"{m.true_max_um:.1f}",
                      f"{m.true_at_s:.3f}", f"{m.eq28_max_um:.1f}",
                      "-" if r is rows[0] else f"{ours.motion_s / m.motion_s:.3f}"]
        body.append(cells)
    title = f"`{Path(program).name}` (time bound {bound:.4f} s)"
    if markdown:
        lines = [title, "", "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
        lines += ["| " + " | ".join(c) + " |" for c in body]
        return "\n".join(lines)
    widths = [max(len(h), *(len(c[i]) for c in body)) for i, h in enumerate(head)]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    return "\n".join([title, fmt.format(*head)] + [fmt.format(*c) for c in body])


def verify_klipper(toolhead_py: Path, programs: list[str], config: MachineConfig) -> int:
    """Run upstream toolhead.py's Move and LookAheadQueue (its C helpers stubbed out: planning
    does not use them) on the same chords and compare every move's trapezoid with ours."""
    import importlib.util
    import types

    for name in ("mcu", "chelper", "kinematics", "kinematics.extruder"):
        sys.modules.setdefault(name, types.ModuleType(name))
    spec = importlib.util.spec_from_file_location("klipper_toolhead", toolhead_py)
    assert spec is not None and spec.loader is not None
    up = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(up)
    vmax = config.interpolator.max_feed_mm_s
    worst = 0.0
    for program in programs:
        pts = flatten(list(read_program(program, config)), 1e-3)
        for accel in (config.interpolator.max_accel_mm_s2, 900.0, 300.0):
            th = types.SimpleNamespace(
                extra_axes=[], max_velocity=vmax, max_accel=accel,
                junction_deviation=KLIPPER_SCV_MM_S**2 * (math.sqrt(2.0) - 1.0) / accel,
                mcr_pseudo_accel=accel * (1.0 - KLIPPER_MCR))
            queue = up.LookAheadQueue()
            queue.set_flush_time(KLIPPER_BUFFER_TIME_HIGH_S)
            done = []
            for a, b in zip(pts[:-1], pts[1:], strict=True):
                if queue.add_move(up.Move(th, [*a, 0.0, 0.0], [*b, 0.0, 0.0], vmax)):
                    done += queue.flush(lazy=True)
            done += queue.flush()
            ref = np.array([[m.accel_t, m.cruise_t, m.decel_t, m.start_v, m.cruise_v]
                            for m in done])
            mv = klipper_plan(pts, vmax, vmax, accel)
            got = np.column_stack([mv.accel_t, mv.cruise_t, mv.decel_t, mv.start_v, mv.cruise_v])
            diff = float(np.abs(ref - got).max()) if len(ref) == len(got) else math.inf
            worst = max(worst, diff)
            print(f"{Path(program).name} A {accel:g}: {len(done)} moves upstream, {len(got)} "
                  f"ported; max difference of phase times and speeds {diff:.3g}")
    return 0 if worst < 1e-9 else 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("programs", nargs="*", default=[str(REPO / p) for p in PROGRAMS])
    ap.add_argument("--tolerances-um", type=float, nargs="+", default=[1.0, 10.0])
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--grbl-ideal", action="store_true",
                    help="sample grbl on its ideal trapezoids, not its 10 ms stepper segments")
    ap.add_argument("--grbl-buffer", type=int, default=GRBL_BLOCK_BUFFER_SIZE - 1,
                    help="blocks grbl plans over (grbl 1.1: 15)")
    ap.add_argument("--no-ablation", action="store_true",
                    help="leave out the peers run with our servo pre-compensation")
    ap.add_argument("--config", help="machine configuration (default: the built-in one)")
    ap.add_argument("--verify-klipper", metavar="TOOLHEAD_PY",
                    help="compare klipper_plan with upstream klippy/toolhead.py and exit")
    args = ap.parse_args(argv)
    config = load_config(args.config)
    if args.verify_klipper:
        return verify_klipper(Path(args.verify_klipper), args.programs, config)

    def log(msg: str) -> None:
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    limit_um = planning_limit_mm(config) * 1e3
    print(f"True contour error target {limit_um:.2f} um (eps_max less the quantisation "
          f"margin); settling {SETTLE_S} s included.\n")
    for program in args.programs:
        rows, bound = bench_program(program, config, args.tolerances_um, log,
                                    not args.grbl_ideal, args.grbl_buffer, not args.no_ablation)
        print(table(program, rows, bound, args.markdown) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
