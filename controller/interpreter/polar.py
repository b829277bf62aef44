"""LinuxCNC's polar coordinates: `@` (radius) and `^` (angle, degrees) in place of X and Y.

The pole is always the work origin X0 Y0 of the program's frame (LinuxCNC's interp_find.cc):
in G90 `@` is the radius and `^` the angle from it; a word left out keeps the current point's
radius or angle. In G91 `@` adds to the radius and `^` to the angle of the current point, both
still about the work origin (so `G91 G1 @-1 ^5` spirals in). Only in G17, never with X or Y.
"""

from __future__ import annotations

import math

from controller.interpreter.codes import WordError
from controller.interpreter.modal import Modal

POLAR_LETTERS = frozenset("@^")


def has_polar(vals: dict[str, float]) -> bool:
    return "@" in vals or "^" in vals


def _word(vals: dict[str, float]) -> str:
    return "@" if "@" in vals else "^"


def check_polar(
    vals: dict[str, float], groups: dict[str, int], modal: Modal, axis_code: bool
) -> None:
    """The rules a line with `@` or `^` must follow. `groups`: the line's codes by modal group
    (its G17, G53 and motion code count); `axis_code`: the line has G10, G28, G30, G92 or
    G43.1, which take axis words for themselves."""
    motion = groups.get("motion", modal.motion)  # code10; None or G80: no motion
    plane = groups.get("plane", modal.plane)
    machine = groups.get("non-modal") == 530
    word = _word(vals)
    if axis_code or motion in (None, 800):
        raise WordError(
            word,
            f"polar coordinates ({word}) can only be used for motion "
            "(G0 G1 G2 G3 G5.1, canned cycles, probes)",
        )
    if plane != 170:
        raise WordError(word, f"polar coordinates ({word}) only in the XY plane (G17)")
    for axis in "XY":
        if axis in vals:
            raise WordError(
                axis,
                f"{axis} word with polar coordinates (@ ^) on one line: "
                "they replace X and Y; use one or the other",
            )
    if machine:
        raise WordError(word, f"polar coordinates ({word}) cannot be used with G53")


def polar_xy(vals: dict[str, float], x: float, y: float, absolute: bool) -> tuple[float, float]:
    """The end point (program frame and units) of a line's `@ ^` from the current point (x, y)
    in that frame, under G90 (`absolute`) or G91."""
    at_origin = x == 0.0 and y == 0.0
    if absolute:
        if "@" in vals and "^" not in vals and at_origin:
            raise WordError(
                "@", "@ without ^ at the work origin: the angle is undefined; give ^ too"
            )
        radius = vals["@"] if "@" in vals else math.hypot(x, y)
        theta = math.radians(vals["^"]) if "^" in vals else math.atan2(y, x)
        return radius * math.cos(theta), radius * math.sin(theta)
    if at_origin:
        raise WordError(
            _word(vals),
            "G91 polar move at the work origin: the angle is undefined (move off X0 Y0 first)",
        )
    return polar_step(x, y, vals.get("@", 0.0), math.radians(vals.get("^", 0.0)))


def polar_step(
    x: float, y: float, radius_step: float, theta_step_rad: float
) -> tuple[float, float]:
    """(x, y) moved by `radius_step` along its radius and then turned by `theta_step_rad` about
    the origin (LinuxCNC's order; a zero step changes nothing, as there)."""
    if radius_step:
        radius = math.hypot(x, y) + radius_step
        theta = math.atan2(y, x)
        x, y = radius * math.cos(theta), radius * math.sin(theta)
    if theta_step_rad:
        radius = math.hypot(x, y)
        theta = math.atan2(y, x) + theta_step_rad
        x, y = radius * math.cos(theta), radius * math.sin(theta)
    return x, y


def cycle_polar(
    vals: dict[str, float], x: float, y: float, absolute: bool
) -> tuple[tuple[float, float], tuple[float, float]]:
    """A canned cycle's `@ ^` (LinuxCNC's convert_cycle_xy): in G90 the hole's point (no check
    at the origin there: atan2(0, 0) is 0); in G91 the (radius, angle in radians) step that
    every repeat adds. Returns ((x, y), (radius step, angle step))."""
    if absolute:
        radius = vals["@"] if "@" in vals else math.hypot(x, y)
        theta = math.radians(vals["^"]) if "^" in vals else math.atan2(y, x)
        return (radius * math.cos(theta), radius * math.sin(theta)), (0.0, 0.0)
    return (x, y), (vals.get("@", 0.0), math.radians(vals.get("^", 0.0)))


def cycle_step(x: float, y: float, polar: tuple[float, float]) -> tuple[float, float]:
    """One repeat's polar step of a G91 cycle; at the work origin it is undefined."""
    if (polar[0] or polar[1]) and x == 0.0 and y == 0.0:
        raise WordError(
            "@" if polar[0] else "^",
            "G91 polar cycle at the work origin: the angle is undefined (move off X0 Y0 first)",
        )
    return polar_step(x, y, *polar)
