"""A simulated table's home switches, index marks and true position (options of the simulators)."""

from __future__ import annotations

from typing import Any

import numpy as np

from controller.errors import DriveError
from drivers.homing import HomingPlan
from drivers.sim.axes import SimAxes
from drivers.sim.homing import AxisHoming, SimAxesHoming

SWITCH_OPTIONS = frozenset({"true_start_mm", "home_switch_mm", "index_pitch_mm",
                            "homed_at_start"})


def per_axis(who: str, key: str, value: Any, n: int, allow_none: bool = False) -> list[Any]:
    """A list option with one number per axis (None allowed where allow_none)."""
    if not isinstance(value, list | tuple) or len(value) != n:
        raise DriveError(f"{who}: option {key!r} must be a list of {n} values (one per axis), "
                         f"got {value!r}")
    out = []
    for v in value:
        if v is None and allow_none:
            out.append(None)
        elif isinstance(v, bool) or not isinstance(v, int | float):
            raise DriveError(f"{who}: option {key!r}: {v!r} is not a number"
                             + (" (or null: no switch)" if allow_none else ""))
        else:
            out.append(float(v))
    return out


class SimSwitches:
    """true_start_mm (list: where the table really is at power-up; default: where the counters
    say), home_switch_mm (list: each axis's switch in that true frame; default: where the homing
    asks home to be, so that a homed table's counters are true; null: no switch on that axis),
    index_pitch_mm (1.0: index marks at its multiples, true frame), homed_at_start (false).
    offset_mm is true minus counter frame, per axis."""

    def __init__(self, n_axes: int, options: dict[str, Any], counter_mm: np.ndarray,
                 who: str) -> None:
        self.who = who
        true_start = options.get("true_start_mm")
        self.offset_mm = np.zeros(n_axes) if true_start is None else \
            np.array(per_axis(who, "true_start_mm", true_start, n_axes)) - counter_mm
        switch = options.get("home_switch_mm")
        self.switch_mm = None if switch is None else per_axis(who, "home_switch_mm", switch,
                                                              n_axes, allow_none=True)
        pitch = options.get("index_pitch_mm", 1.0)
        if isinstance(pitch, bool) or not isinstance(pitch, int | float) or not pitch > 0:
            raise DriveError(f"{who}: option 'index_pitch_mm' must be a positive number, "
                             f"got {pitch!r}")
        self.index_pitch_mm = float(pitch)
        homed = options.get("homed_at_start", False)
        if not isinstance(homed, bool):
            raise DriveError(f"{who}: option 'homed_at_start' must be true or false, "
                             f"got {homed!r}")
        if homed and np.abs(self.offset_mm).max(initial=0.0) > 1e-9:
            raise DriveError(f"{who}: homed_at_start says the counters are true, but "
                             "true_start_mm differs from where they start")
        self.homed_at_start = homed

    def switch_for(self, axis: int, plan: HomingPlan) -> float | None:
        return plan.home_mm if self.switch_mm is None else self.switch_mm[axis]

    def homing(self, axes: SimAxes, plans: dict[int, HomingPlan], period_s: float,
               names: tuple[str, ...]) -> SimAxesHoming:
        """A homing run of these axes on the simulated plant, from where they stand."""
        seqs = {i: AxisHoming(plan, float(axes.commanded[i] * axes.pulse_mm[i]),
                              float(axes.pulse_mm[i]), period_s, self.switch_for(i, plan),
                              self.index_pitch_mm)
                for i, plan in plans.items()}
        return SimAxesHoming(axes, self.offset_mm, seqs, names)


def timeout_message(timeout_s: float) -> str:
    return f"time-out: not homed within {timeout_s:g} s"
