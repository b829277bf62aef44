"""The braking acceleration of each stop, guessed before any plan from the servo model's
overshoot of a straight cruise braked to rest; Figure 4's loop checks it on the real path."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig
from controller.servo.band import band_servos
from controller.servo.model import tracking_error_mm

SETTLE_AFTER_S = 0.06  # the model's settling after the stop


class BrakingModel:
    """A first guess of each stop's braking acceleration, before any plan: the overshoot of a
    straight cruise at v braked to rest by a quintic of peak acceleration A, through each axis
    model; the largest A (a bisection) whose overshoot is within the target. The loop then
    checks it on the real path. Memoised by speed on a 0.1 mm/s grid (the overshoot is not
    monotonic in the speed: between grid speeds it may be a little over the target, which is
    5 % under the limit, and the loop measures the real path anyway)."""

    CRUISE_S = 0.03  # the cruise before the braking: the servo is in its steady lag by then

    def __init__(self, config: MachineConfig, target_mm: float) -> None:
        # Every axis filter of the servo band's plants (the model's alone without one).
        self.servos = list({id(s): s for pair in band_servos(config) for s in pair}.values())
        self.period_s = config.sample_period_s
        self.accel_mm_s2 = config.interpolator.max_accel_mm_s2
        self.target_mm = target_mm
        self._memo: dict[float, float] = {}

    def overshoot_mm(self, v_mm_s: float, accel_mm_s2: float) -> float:
        T = self.period_s  # noqa: N806
        brake_s = 15.0 * v_mm_s / (8.0 * accel_mm_s2)
        tau = np.minimum(np.arange(1, int(np.ceil(brake_s / T)) + 1) * T / brake_s, 1.0)
        v = np.r_[np.full(int(self.CRUISE_S / T), v_mm_s),
                  v_mm_s * (1.0 - tau ** 3 * (10.0 + tau * (-15.0 + 6.0 * tau))),
                  np.zeros(int(SETTLE_AFTER_S / T))]
        x = np.cumsum(v) * T
        # How far past the stop each axis model's actual position (x - e) gets.
        return max(float(np.max(x - tracking_error_mm(servo, v) - x[-1]))
                   for servo in self.servos)

    def accel_for(self, v_mm_s: float) -> float:
        """The braking acceleration for an approach at v (the full one when that is fine)."""
        key = np.ceil(v_mm_s * 10.0) / 10.0
        if key not in self._memo:
            self._memo[key] = self._search(float(key))
        return self._memo[key]

    def _search(self, v_mm_s: float) -> float:
        if v_mm_s <= 0.0 or self.overshoot_mm(v_mm_s, self.accel_mm_s2) <= self.target_mm:
            return self.accel_mm_s2
        lo, hi = 0.05 * self.accel_mm_s2, self.accel_mm_s2
        for _ in range(12):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.overshoot_mm(v_mm_s, mid) <= self.target_mm else (lo, mid)
        return lo
