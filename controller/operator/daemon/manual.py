"""The daemon's manual operations: homing the axes and jogging them, within the soft limits."""

from __future__ import annotations

import threading
from typing import Any, Protocol

from controller.config import MachineConfig
from controller.errors import CncError
from controller.interpreter.state import MIN_FEED_MM_MIN
from controller.operator.daemon.log import ERR, NOTICE, EventLog
from controller.operator.daemon.protocol import ProtocolError
from drivers.base import Drive
from drivers.homing import homing_groups


class ManualHost(Protocol):
    """What homing needs of the daemon's Machine (machine.py imports this module)."""

    config: MachineConfig
    drive: Drive
    log: EventLog
    last_homing: str | None

    @property
    def lock(self) -> threading.RLock: ...

    def require_idle(self) -> None: ...

    def require_position(self, what: str) -> None: ...

    def set_state_homing(self) -> None: ...

    def end_homing(self, failure: str | None) -> None: ...

    def position_text(self) -> str: ...

HOMING_TIMEOUT_S = 120.0
JOG_FEED_MM_MIN = 600.0  # default jog feed
LIMIT_MARGIN_MM = 1e-3  # a jog stops this far inside the travel (the pulse it would round to)


def unhomed_axes(config: MachineConfig, homed: tuple[bool, ...]) -> list[str]:
    """Axes with a homing sequence not yet homed (axes without one are absolute)."""
    return [a.name.upper() for a, h in zip(config.axes, homed, strict=True)
            if a.homing is not None and not h]


def start_homing(machine: ManualHost, axis_names: list[str]) -> None:
    """Home the named axes (all with a homing sequence if none named), group by group, in a
    thread; the machine is HOMING meanwhile and IDLE (or FAULT) after."""
    config = machine.config
    wanted = {n.lower() for n in axis_names} or {a.name for a in config.axes if a.homing}
    unknown = wanted - set(config.axis_names)
    if unknown:
        raise ProtocolError("bad-field", f"no axis {sorted(unknown)[0].upper()}")
    without = [n.upper() for n in sorted(wanted) if config.axis(n).homing is None]
    if without:
        raise ProtocolError("bad-field", f"axis {without[0]} has no homing sequence "
                                         "(its position is absolute)")
    groups = [tuple(i for i in g if config.axes[i].name in wanted) for g in homing_groups(config)]
    groups = [g for g in groups if g]
    with machine.lock:
        machine.require_idle()
        machine.require_position("home")
        machine.last_homing = None  # this homing's word comes when it ends
        machine.set_state_homing()
    threading.Thread(target=_home_groups, args=(machine, groups), name="homing",
                     daemon=True).start()


def _home_groups(machine: ManualHost, groups: list[tuple[int, ...]]) -> None:
    names = lambda g: ", ".join(machine.config.axes[i].name.upper() for i in g)  # noqa: E731
    try:
        for group in groups:
            machine.log.log(NOTICE, f"homing {names(group)}")
            machine.drive.home(group, timeout_s=HOMING_TIMEOUT_S)
            machine.log.log(NOTICE, f"homed {names(group)}: {machine.position_text()}")
        machine.end_homing(None)
    except CncError as exc:
        machine.log.log(ERR, f"homing failed: {exc}")
        machine.end_homing(str(exc))


def jog_program(config: MachineConfig, position_mm: dict[str, float], axis: str,
                distance_mm: float | None, direction: int, feed_mm_min: float) -> tuple[str, str]:
    """A one-line program moving one axis (incremental distance, or toward the soft limit for
    a continuous jog), clipped to the travel: (program text, what it does)."""
    if axis not in config.axis_names:
        raise ProtocolError("bad-field", f"no axis {axis.upper()}")
    if not MIN_FEED_MM_MIN <= feed_mm_min <= config.interpolator.max_feed_mm_s * 60.0:
        raise ProtocolError("bad-field", f"jog feed must be from {MIN_FEED_MM_MIN:g} to the "
                                         "maximum feed "
                                         f"{config.interpolator.max_feed_mm_s * 60:g} mm/min")
    lo, hi = config.axis(axis).travel_mm
    here = position_mm[axis]
    wanted = here + distance_mm if distance_mm is not None else (hi if direction > 0 else lo)
    target = min(max(wanted, lo + LIMIT_MARGIN_MM), hi - LIMIT_MARGIN_MM)
    if abs(target - here) < config.axis(axis).pulse_mm:
        raise ProtocolError("at-limit", f"{axis.upper()} is at {here:.3f}: "
                            + ("at the soft limit" if target != wanted else "nothing to move"))
    if distance_mm is not None and target != wanted:
        note = f"jog {axis.upper()} to {target:.3f} (stopped at the soft limit)"
    else:
        note = f"jog {axis.upper()} to {target:.3f}"
    text = f"G21 G90 G64 G1 {axis.upper()}{target:.4f} F{feed_mm_min:.3f}\nM2\n"
    return text, note


def homed_status(machine: ManualHost) -> dict[str, Any]:
    try:
        homed = machine.drive.homed()
    except CncError:
        return {}
    return {a.name: bool(h) for a, h in zip(machine.config.axes, homed, strict=True)}
