"""The serial card's homing, host side: one HOME request, then the reports until it is done."""

from __future__ import annotations

import time
from typing import Any

from drivers.errors import HomingError, LostCommunicationError
from drivers.homing import HomingPlan, plan_for
from drivers.serial import protocol as p

# drivers.serial.backend.SerialCard, whose link internals this uses (not imported: the backend
# imports this module, and tests/test_layers.py counts a TYPE_CHECKING import as a cycle too).
SerialCard = Any

ABORT_WAIT_S = 2.0  # after a time-out: how long the axes may take to stop


def _pulses(card: SerialCard, what: str, axis: str, value: float, pulse_mm: float,
            lo: int = 1) -> int:
    out = round(value / pulse_mm)
    if out < lo:
        raise HomingError(f"{axis.upper()} axis: {what} {value:g} is below one pulse per "
                          "second (s^2) on the card", axis)
    return out


def request_for(card: SerialCard, axes: tuple[int, ...]) -> tuple[int, list[p.HomeAxis],
                                                                  dict[int, HomingPlan]]:
    """Axis mask, the HOME frame's per-axis blocks (pulses) and the plans (mm)."""
    blocks = [p.HomeAxis() for _ in range(card.n_axes)]
    plans = {}
    for i in axes:
        plan = plans[i] = plan_for(card.config, i)
        pulse = float(card.pulse_mm[i])
        final_mm = plan.final_mm if plan.final_mm is not None else plan.home_mm
        blocks[i] = p.HomeAxis(
            direction=plan.direction, use_index=plan.use_index,
            search_pps=_pulses(card, "search speed", plan.axis, plan.search_mm_s, pulse),
            latch_pps=_pulses(card, "latch speed", plan.axis, plan.latch_mm_s, pulse),
            accel_pps2=_pulses(card, "acceleration", plan.axis, plan.accel_mm_s2, pulse),
            home_pulses=round(plan.home_mm / pulse), final_pulses=round(final_mm / pulse),
            search_limit_pulses=round(plan.search_limit_mm / pulse))
    return sum(1 << i for i in axes), blocks, plans


def home(card: SerialCard, axes: tuple[int, ...], timeout_s: float) -> None:
    """Send HOME, wait for a report without HOMING; HomingError with the card's reason."""
    mask, blocks, plans = request_for(card, axes)
    try:
        reply = card._request(lambda token: p.encode_home(token, mask, blocks), "HOME request")
    except p.ProtocolError as exc:
        raise HomingError(f"cannot home: {exc}") from exc
    except LostCommunicationError as exc:
        if card._lost is not None:
            raise
        raise HomingError(f"the card on {card.port} did not answer HOME within "
                          f"{card.reply_timeout_s:g} s (a card without homing drops the frame "
                          "as garbage)") from exc
    names = card.config.axis_names
    if reply.latched & p.ST_HOME_FAILED:
        raise _failure(card, reply, plans, names)
    deadline_s = time.monotonic() + timeout_s
    with card._cond:
        seen = card._status_frames
    while True:
        with card._cond:
            last = card._last
            if card._status_frames > seen and last is not None \
                    and not last.latched & p.ST_HOMING:
                break
            left_s = deadline_s - time.monotonic()
            if left_s <= 0 or card.homing_aborted():
                break
            card._cond.wait(min(left_s, 0.05))
        card._check_link()  # a silent card or a closed port: LostCommunicationError
    if last is None or last.latched & p.ST_HOMING:
        _abort(card)
        axis = names[axes[0]]
        why = card.homing_aborted() or f"time-out: not homed within {timeout_s:g} s"
        raise HomingError(f"{axis.upper()} axis homing failed: {why} (the card was reset: "
                          "homing aborted)", axis)
    if last.latched & (p.ST_HOME_FAILED | p.ST_DRIVE_FAULT):
        raise _failure(card, last, plans, names)


def _abort(card: SerialCard) -> None:
    """RESET stops a homing sequence; wait (bounded) until the axes report it has ended."""
    card._sync(card._request(p.encode_reset, "reset"))
    deadline_s = time.monotonic() + ABORT_WAIT_S
    with card._cond:
        while card._last is not None and card._last.latched & p.ST_HOMING \
                and card._lost is None and time.monotonic() < deadline_s:
            card._cond.wait(0.05)


def _failure(card: SerialCard, s: p.Status, plans: dict[int, HomingPlan],
             names: tuple[str, ...]) -> HomingError:
    axis = names[s.fault_axis] if s.fault_axis < len(names) else f"#{s.fault_axis}"
    if s.latched & p.ST_DRIVE_FAULT:
        return HomingError(f"{axis.upper()} axis homing failed: drive fault during homing: "
                           f"{card._fault_message()}", axis)
    reason = p.HOME_REASONS.get(s.fault_code, f"homing failure code {s.fault_code}")
    plan = plans.get(s.fault_axis)
    if s.fault_code == p.HOME_NOT_FOUND and plan is not None:
        reason = (f"home switch not found within {plan.search_limit_mm:.1f} mm "
                  "(the travel + 10 %)")
    return HomingError(f"{axis.upper()} axis homing failed: {reason}", axis)
