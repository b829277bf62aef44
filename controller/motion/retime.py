"""Feed hold and feed override: the planned reference re-timed along its own path, within Amax."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.config import MachineConfig
from controller.motion.hold_ramp import PathRamp, hold_distances_mm, hold_shape, hold_steps
from controller.servo.model import filter_block
from controller.servo.prediction import (
    SETTLE_S,
    axis_servos,
    planning_limit_mm,
    rest_state,
)
from controller.servo.true_distance import distance_from_reference_mm

ACCEL_MARGIN = 0.98  # first guess of a ramp: this share of Amax for the rate change alone
MIN_RAMP_S = 0.01
MAX_RAMP_S = 5.0
RAMP_GROWTH = 1.25  # a ramp that breaks Amax is tried again this much longer
AT_REST_RATE = 1e-9  # a time scale below this is a standstill
SERVO_MEMORY = 256  # output samples kept to start the servo model of a check (settles in 32)
MAX_RATE = 1.5  # feed override 150 %
HORIZON_ROWS = 600  # above 100 %: rows looked at ahead for what would break a limit
RATE_STEP = 0.05  # above 100 %: the scale goes up in steps this big (no ramp per row)
CAP_EVERY_ROWS = 20  # ... looked at again after this many rows (the horizon is 600)
CONTOUR_SHARE = 0.9  # above 100 %: the plan's error times rate^2 kept within this of the limit
HOLD_MEMORY = 96  # outputs that start the model of a hold's check (its slowest mode, 11 ms,
#                  has died away to 0.02 % in them)
HOLD_TRIES = 5  # a hold's ramp: at Amax, then (if the model check fails) longer; a bound
HOLD_MARGIN = 1.1  # ... by the error's ratio to the limit and this margin
HOLD_GROWTH_MIN, HOLD_GROWTH_MAX = 1.5, 4.0  # ... at least and at most this much a try


def smoothstep5(u: np.ndarray) -> np.ndarray:
    """The quintic 0 -> 1 with zero slope and curvature at both ends (docs/algorithms.md,
    Feed planning)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def interpolate_rows(rows: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Catmull-Rom through the rows at fractional indices tau (exact at whole ones); past the
    last row, the last row (the reference at rest)."""
    n = len(rows)
    tau = np.clip(tau, 0.0, n - 1)
    i = np.minimum(np.floor(tau).astype(np.int64), n - 1)
    t = (tau - i)[:, None]
    p0, p1 = rows[np.maximum(i - 1, 0)], rows[i]
    p2, p3 = rows[np.minimum(i + 1, n - 1)], rows[np.minimum(i + 2, n - 1)]
    c1 = 0.5 * (p2 - p0)
    c2 = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3
    c3 = 0.5 * (p3 - p0) + 1.5 * (p1 - p2)
    return p1 + t * (c1 + t * (c2 + t * c3))


@dataclass
class Ramp:
    """The time scale (reference samples per output sample) going rate0 -> rate1 over `span`
    samples (not always a whole number: see Retimer._land)."""

    rate0: float
    rate1: float
    span: float
    k: int = 0  # samples of it done

    @property
    def n(self) -> int:
        return max(1, math.ceil(self.span - 1e-9))

    def rates(self, count: int) -> np.ndarray:
        """The next `count` rates (rate1 once the ramp is over); does not advance."""
        k = self.k + 1 + np.arange(count)
        return self.rate0 + (self.rate1 - self.rate0) * smoothstep5(k / max(self.span, 1.0))

    @property
    def done(self) -> bool:
        return self.k >= self.n


class Retimer:
    """Plays the planned reference at a time scale `rate` (1: as planned, 0: held).

    Positions are taken along the reference rows themselves (the planned path: no new
    geometry), so the feed is rate x the planned feed and the normal acceleration rate^2 x
    the planned one: below 1 neither can exceed what the plan was checked for. A change of
    rate is a quintic ramp, lengthened until the tangential acceleration of the re-timed
    points, rate^2 a + rate' v, stays within Amax on the rows it will cross, and until the
    servo model's distance of the tool from the points sent stays within the contour limit
    (a standstill's settling included), or no worse than the plan's own there. A ramp to
    rest (a hold, 0 %) is a stop shape at Amax by arc length instead (_hold_ramp,
    motion/hold_ramp.py). At rate 1 with no ramp the rows pass through unchanged: a run
    without hold or override is the plan.
    """

    def __init__(self, config: MachineConfig) -> None:
        self.n_axes = len(config.axes)
        self.period_s = config.sample_period_s
        self.accel_mm_s2 = config.interpolator.max_accel_mm_s2
        self.servos = axis_servos(config)
        self.limit_mm = planning_limit_mm(config)
        self.settle = int(round(SETTLE_S / self.period_s))
        self.recent = np.zeros((0, 2))  # the last outputs (XY), the servo model's history
        self.max_feed_mm_s = config.interpolator.max_feed_mm_s
        self.rate = 1.0
        self.target = 1.0
        self.wanted = 1.0  # the operator's override; above 1 governed by the rows ahead
        self.rows_passed = 0  # rows crossed since the start (the governor's clock)
        self.cap_at: int | None = None  # when the rows ahead were last looked at
        self.cap_goal = 1.0
        self.cap_wanted = 1.0
        self.shape = hold_shape(config.interpolator.ramp_share)  # a hold's ramp
        self.ramp: Ramp | PathRamp | None = None
        self.frac = 0.0  # position between the last row passed and the first held row
        self.back = np.zeros((0, self.n_axes + 2))  # the two last rows passed (interpolation)

    @property
    def identity(self) -> bool:
        return self.rate == 1.0 and self.ramp is None and self.frac == 0.0 \
            and self.target == 1.0 and self.wanted == 1.0

    @property
    def at_rest(self) -> bool:
        return self.rate <= AT_REST_RATE and self.ramp is None

    def set_target(self, rate: float) -> None:
        """Ask for a new time scale; the ramp is planned at the next take(). Above 1 the
        scale is whatever the rows ahead allow up to it (see _governed)."""
        self.wanted = min(max(rate, 0.0), MAX_RATE)
        self.target = min(self.wanted, 1.0)

    def passed(self, rows: np.ndarray) -> None:
        """Rows sent as they are (identity): remember the last two for a later ramp."""
        if len(rows):
            self.back = np.vstack([self.back, rows])[-SERVO_MEMORY:]
            self._remember(rows)

    def _remember(self, rows: np.ndarray) -> None:
        self.recent = np.vstack([self.recent, rows[-SERVO_MEMORY:, :2]])[-SERVO_MEMORY:]

    # -- output ---------------------------------------------------------------------------
    def take(self, held: np.ndarray, limit: int, count: int,
             land: bool = False) -> tuple[np.ndarray, int]:
        """Up to `count` output rows crossing at most `limit` held rows: (rows, rows passed).

        A new target starts a ramp planned on the held rows; rows past `limit` are only
        looked at, never reached. land: the limit row is a standstill of the plan (a pause,
        the program end), so the last output lands on it exactly when less than a row away."""
        if self.identity:
            n = max(0, min(count, limit))
            self.passed(held[:n])
            return held[:n], n
        self.plan(held)
        if self.at_rest or count <= 0:
            return np.zeros((0, held.shape[1])), 0
        rates = self._rates(count)
        base = np.vstack([self.back, held]) if len(self.back) else held
        start = len(self.back) - 1 + self.frac  # fractional index of the last output point
        tau = start + np.cumsum(rates)
        top = len(self.back) - 1 + limit
        keep = int(np.searchsorted(tau, top + 1e-12, side="right"))
        tau, rates = tau[:keep], rates[:keep]
        if land and keep < count and limit > 0 and top - (tau[-1] if keep else start) < 1.0:
            tau = np.append(tau, float(top))  # the rest of a row at a standstill: land on it
            rates = np.append(rates, rates[-1] if keep else self.rate)
        self._advance(rates)
        if self.ramp is None and self.rate == 1.0 and len(tau) \
                and abs(tau[-1] - round(tau[-1])) < 1e-6:
            tau[-1] = round(tau[-1])  # back on whole rows (see _land): the rows as planned
        out = self._rows(base, tau, rates)
        if len(out):
            self._remember(out)
        end = start if not len(tau) else float(tau[-1])
        whole = int(math.floor(end + 1e-12))
        passed = max(0, whole - (len(self.back) - 1))
        self.frac = max(0.0, end - whole) if end - whole > 1e-12 else 0.0
        self.back = base[max(0, whole - SERVO_MEMORY + 1): whole + 1].copy()  # not a view:
        # the journal of sends keeps it, and a view would keep all of `base` alive
        self.rows_passed += passed
        return out, passed

    def plan(self, held: np.ndarray) -> None:
        """What take() does first: a target above 1 governed by the rows ahead, the ramp to a
        new target planned on the held rows (a hold plans it before taking frames back)."""
        if self.wanted > 1.0 or self.rate > 1.0 or (self.ramp and self.ramp.rate1 > 1.0):
            self.target = self._governed(held)
        if self.target != (self.ramp.rate1 if self.ramp else self.rate):
            self.ramp = self._plan_ramp(held)

    def _rows(self, base: np.ndarray, tau: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """Positions at tau; the feed column scaled by the rate; lines (and marks) of the row
        reached, so a pause mark is only carried by the row that lands on it."""
        if not len(tau):
            return np.zeros((0, base.shape[1]))
        pos = interpolate_rows(base[:, : self.n_axes + 1], tau)
        pos[:, self.n_axes] *= rates
        idx = np.minimum(np.floor(tau + 1e-12).astype(np.int64), len(base) - 1)
        exact = np.abs(tau - idx) <= 1e-12
        line = np.where(exact, base[idx, -1], np.floor(np.abs(base[idx, -1])))
        return np.column_stack([pos, line])

    def _rates(self, count: int) -> np.ndarray:
        if self.ramp is None:
            return np.full(count, self.rate)
        return self.ramp.rates(count)

    def _advance(self, rates: np.ndarray) -> None:
        if not len(rates):
            return
        self.rate = float(rates[-1])
        if self.ramp is not None:
            self.ramp.k += len(rates)
            if self.ramp.done:
                self.rate, self.ramp = self.ramp.rate1, None
                if self.rate <= AT_REST_RATE:
                    self.rate = 0.0

    # -- planning -------------------------------------------------------------------------
    def _plan_ramp(self, held: np.ndarray) -> Ramp | PathRamp | None:
        """The ramp to the target: to rest, the hold's (_hold_ramp); otherwise the shortest
        quintic ramp that keeps Amax and the contour limit."""
        rate0, rate1 = self.rate, self.target
        if rate0 == rate1:
            return None
        base = np.vstack([self.back, held]) if len(self.back) else held
        if rate1 == 0.0 and len(base) >= 2:
            return self._hold_ramp(base)
        v_max = float(np.max(np.abs(base[:, self.n_axes]))) if len(base) else 0.0
        guess_s = 15.0 * abs(rate1 - rate0) * v_max / (8.0 * ACCEL_MARGIN * self.accel_mm_s2)
        ramp_s = max(MIN_RAMP_S, guess_s)
        plan_mm = self._worst_distance_mm(base, Ramp(rate0, rate0, 1))
        while True:
            ramp = Ramp(rate0, rate1, float(math.ceil(ramp_s / self.period_s)))
            if rate1 == 1.0:
                ramp = self._land(ramp)
            if ramp_s >= MAX_RAMP_S or self._acceptable(base, ramp, plan_mm):
                return ramp
            ramp_s *= RAMP_GROWTH

    def _hold_ramp(self, base: np.ndarray) -> PathRamp:
        """To rest from the path speed now: the hold's stop shape at Amax along the rows by arc
        length (so the plan's own acceleration there does not add to it), checked once on the
        servo model (the tool within the contour limit, or no worse than the plan's own there,
        through its standstill and settling). Only if that fails (without pre-compensation
        a stop at Amax leaves the path by about twice the limit), longer by the ratio of the
        error to the limit, at most HOLD_TRIES times in all; the last is kept whatever it
        gives."""
        tau0 = max(0.0, len(self.back) - 1 + self.frac)
        feed = float(np.interp(tau0, np.arange(len(base)), np.abs(base[:, self.n_axes])))
        pos = base[:, : self.n_axes]
        plan_mm: float | None = None
        stretch = 1.0
        for _ in range(HOLD_TRIES):
            dist = hold_distances_mm(self.rate * feed, self.accel_mm_s2, self.period_s,
                                     self.shape, stretch)
            # Ends on a sample that does not move: the feed sent there (rate x the row's) is 0.
            ramp = PathRamp(np.append(hold_steps(pos, tau0, dist, max(1.0, self.rate)), 0.0))
            worst_mm = self._worst_distance_mm(base, ramp, HOLD_MEMORY)
            if worst_mm <= self.limit_mm:
                break
            if plan_mm is None:  # only now: what the plan itself gives there
                plan_mm = self._worst_distance_mm(base, Ramp(self.rate, self.rate, 1),
                                                  HOLD_MEMORY)
            if worst_mm <= plan_mm:
                break
            # The error a ramp adds goes about as its deceleration, 1 / its length.
            # Short ramps (a few servo time constants) gain less: at least HOLD_GROWTH_MIN.
            stretch *= min(HOLD_GROWTH_MAX,
                           max(HOLD_GROWTH_MIN, HOLD_MARGIN * worst_mm / self.limit_mm))
        return ramp

    def _land(self, ramp: Ramp) -> Ramp:
        """The same ramp back to rate 1 stretched (by less than 2 / (1 - rate0) samples) so
        that it ends on a whole row: from there the planned rows pass through unchanged,
        where points between rows would differ from them by interpolation (0.1 % in speed)."""
        lo, hi = ramp.span, ramp.span + 2.0 / max(abs(1.0 - ramp.rate0), 1e-3) + 2.0
        horizon = math.ceil(hi) + 1
        down = ramp.rate0 < 1.0  # from below 1 a longer ramp advances less, from above more

        def advance(span: float) -> float:
            return self.frac + float(np.sum(Ramp(ramp.rate0, 1.0, span).rates(horizon)))

        first = advance(lo)
        target = math.floor(first) if down else math.ceil(first)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            short = advance(mid) > target if down else advance(mid) < target
            lo, hi = (mid, hi) if short else (lo, mid)
        return Ramp(ramp.rate0, 1.0, hi)

    # -- above 100 % ------------------------------------------------------------------------
    def _governed(self, held: np.ndarray) -> float:
        """The scale above 1 the rows ahead allow, up to the operator's: the planned feed
        times it within Vmax, its tangential acceleration times its square within Amax, and
        the plan's own contour error (servo model, rate 1) times its square within the limit.
        Down at once when something ahead needs it (the ramp is planned and checked as any),
        up only by whole RATE_STEPs; never below 1 on its account (the plan is checked at 1)."""
        if self.wanted <= 1.0:
            return self.wanted
        now = self.ramp.rate1 if self.ramp else self.rate
        if self.cap_at is not None and self.rows_passed - self.cap_at < CAP_EVERY_ROWS \
                and self.cap_wanted == self.wanted:
            return now if self.cap_goal >= now else self.cap_goal
        goal = self._cap_goal(held)
        self.cap_at, self.cap_goal, self.cap_wanted = self.rows_passed, goal, self.wanted
        return goal if goal < now or goal >= now + RATE_STEP - 1e-9 else now

    def _cap_goal(self, held: np.ndarray) -> float:
        base = np.vstack([self.back, held]) if len(self.back) else held
        i0 = max(0, int(len(self.back) - 1 + self.frac))
        ahead = base[i0: i0 + HORIZON_ROWS]
        if len(ahead) < 2:
            return 1.0
        feed = np.abs(ahead[:, self.n_axes])
        accel = np.abs(np.diff(base[max(0, i0 - 1): i0 + HORIZON_ROWS, self.n_axes])) \
            / self.period_s
        dist = self._plan_distance_mm(base, i0, len(ahead))
        tiny = 1e-12
        cap = min(self.wanted,
                  float(np.min(self.max_feed_mm_s / np.maximum(feed, tiny))),
                  float(np.sqrt(ACCEL_MARGIN * self.accel_mm_s2 / max(accel.max(), tiny))),
                  float(np.sqrt(CONTOUR_SHARE * self.limit_mm / max(dist.max(), tiny))))
        return max(1.0, math.floor(cap / RATE_STEP) * RATE_STEP)

    def _plan_distance_mm(self, base: np.ndarray, i0: int, n: int) -> np.ndarray:
        """The plan's own (rate 1) model distance of the tool from its rows i0.. i0+n, the
        rows before them (up to SERVO_MEMORY) starting the model."""
        xy = base[: i0 + n, :2]
        v = np.diff(xy, axis=0, prepend=xy[:1]) / self.period_s
        sx, sy = rest_state(self.servos)
        err = np.column_stack([filter_block(self.servos[0], v[:, 0], sx)[0],
                               filter_block(self.servos[1], v[:, 1], sy)[0]])
        return distance_from_reference_mm(xy, xy - err)[i0:]

    def _path_points(self, base: np.ndarray, ramp: Ramp | PathRamp, extra: int) -> np.ndarray:
        """The points the ramp would send (all axes), then `extra` more at its final rate, a
        standstill staying where it is; the point sent before them first when known."""
        rates = ramp.rates(ramp.n + extra)
        start = len(self.back) - 1 + self.frac
        tau = start + np.concatenate([[0.0], np.cumsum(rates)])
        return interpolate_rows(base[:, : self.n_axes], tau)

    def _acceptable(self, base: np.ndarray, ramp: Ramp, plan_mm: float) -> bool:
        if len(base) < 2:
            return True
        pts = self._path_points(base, ramp, 2)
        if len(self.recent) >= 2:
            pts = np.vstack([self.recent[-2:-1, :] if self.n_axes == 2 else
                             np.column_stack([self.recent[-2:-1], pts[:1, 2:]]), pts])
        speed = np.linalg.norm(np.diff(pts, axis=0), axis=1) / self.period_s
        if np.any(np.abs(np.diff(speed)) / self.period_s > self.accel_mm_s2):
            return False
        return self._worst_distance_mm(base, ramp) <= max(self.limit_mm, plan_mm)

    def _worst_distance_mm(self, base: np.ndarray, ramp: Ramp | PathRamp,
                           memory: int = SERVO_MEMORY) -> float:
        """The servo model's largest distance of the tool from the points sent, over the ramp
        and a settling time after it, starting from the last `memory` outputs (their state)."""
        if len(base) < 2:
            return 0.0
        new = self._path_points(base, ramp, self.settle)[1:, :2]
        recent = self.recent[-memory:]
        xy = np.vstack([recent, new]) if len(recent) else new
        v = np.diff(xy, axis=0, prepend=xy[:1]) / self.period_s
        sx, sy = rest_state(self.servos)
        err = np.column_stack([filter_block(self.servos[0], v[:, 0], sx)[0],
                               filter_block(self.servos[1], v[:, 1], sy)[0]])
        dist = distance_from_reference_mm(xy, xy - err)
        return float(dist[len(recent):].max(initial=0.0))
