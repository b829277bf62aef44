"""Where `cncctl identify` will move each axis: its excitation within Vmax, Amax, the window
and the travel, the line that says so, the refusals (embedded and in cncd alike), and the
operator's confirmation."""

from __future__ import annotations

from dataclasses import dataclass

from controller.config import MachineConfig
from controller.errors import ConfigError
from controller.operator.identify.loop import LEAD_IN_S, TAIL_S
from controller.operator.run.keys import enter_to_go
from controller.servo.excitation import Excitation, design

MIN_WINDOW_SHARE = 0.5  # the travel may shrink the excitation to half, not further
UNBOUNDED_MM = 1e6
MIN_DURATION_S, MAX_DURATION_S = 1.0, 30.0
MAX_WINDOW_MM = 1e4


class PlanRefused(Exception):
    """No excitation can be made as asked (nothing moved); the message says why."""


@dataclass(frozen=True, eq=False)
class AxisPlan:
    """One axis's excitation from where it stands."""

    index: int
    name: str
    here_mm: float
    excitation: Excitation
    duration_s: float

    def window_text(self) -> str:
        lo, hi = self.excitation.excursion_mm
        exc = self.excitation
        return (f"{self.name.upper()} will move within {self.here_mm + lo:.3f}.."
                f"{self.here_mm + hi:.3f} mm (now {self.here_mm:.3f}; up to "
                f"{exc.peak_velocity_mm_s:.1f} mm/s and {exc.peak_accel_mm_s2:.0f} mm/s^2, "
                f"{LEAD_IN_S + self.duration_s + TAIL_S:.1f} s); the other axes hold")

    def as_dict(self) -> dict[str, object]:
        """What a client is shown before it confirms (the daemon's reply)."""
        lo, hi = self.excitation.excursion_mm
        return {"axis": self.name, "here_mm": self.here_mm, "low_mm": self.here_mm + lo,
                "high_mm": self.here_mm + hi, "text": self.window_text()}


def check_limits(window_mm: float, duration_s: float) -> None:
    if not MIN_DURATION_S <= duration_s <= MAX_DURATION_S or not 0 < window_mm <= MAX_WINDOW_MM:
        raise ConfigError("identify", "--duration/--window",
                          f"duration {MIN_DURATION_S:g} to {MAX_DURATION_S:g} s, window above "
                          f"0 mm (at most {MAX_WINDOW_MM:g})")


def choose_axes(config: MachineConfig, words: list[str]) -> list[int]:
    """The axes named (every axis when none), in order, each once; ConfigError for another."""
    names = [w.lower() for w in words] or list(config.axis_names)
    for n in names:
        if n not in config.axis_names:
            raise ConfigError("identify", n, f"no such axis (the machine has "
                              f"{', '.join(a.upper() for a in config.axis_names)})")
    return [config.axis_names.index(n) for n in dict.fromkeys(names)]


def plan_axes(config: MachineConfig, commanded_counts: list[int], axes: list[int],
              window_mm: float, duration_s: float) -> list[AxisPlan]:
    """Each axis's excitation within Vmax, Amax, the window and the travel; PlanRefused when
    the window or the travel leaves less than half of what Vmax and Amax allow."""
    vmax = config.interpolator.max_feed_mm_s
    amax = config.interpolator.max_accel_mm_s2
    plans = []
    for i in axes:
        a = config.axes[i]
        here = float(commanded_counts[i]) * a.pulse_mm
        # What Vmax and Amax alone allow; the window and the travel may cut it to half.
        wanted = design(config.sample_period_s, min(vmax, a.max_velocity_mm_s), amax,
                        UNBOUNDED_MM, duration_s)
        need = max(-wanted.excursion_mm[0], wanted.excursion_mm[1])
        room = min(window_mm, here - a.travel_mm[0], a.travel_mm[1] - here)
        if room < MIN_WINDOW_SHARE * need:
            raise PlanRefused(f"travel too short: {a.name.upper()} stands at {here:.3f} mm, "
                              f"{max(room, 0.0):.3f} mm from its travel limit or the window; "
                              f"identify needs {need:.3f} mm either side")
        exc = wanted if room >= need else design(
            config.sample_period_s, min(vmax, a.max_velocity_mm_s), amax, room, duration_s)
        plans.append(AxisPlan(i, a.name, here, exc, duration_s))
    return plans


def confirm_start(yes: bool) -> bool:
    """Enter starts (or --yes); Ctrl-C, a stop signal or the end of standard input do not."""
    return yes or enter_to_go("cncctl: press Enter to start, Ctrl-C to cancel")
