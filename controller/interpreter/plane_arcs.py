"""G2/G3 in the plane in force (G17 XY, G18 ZX, G19 YZ): the centre from its offset words or R,
and the block: an ArcBlock for a G17 arc at constant Z (the XY contour path), a HelixBlock for
a G17 arc with a Z end and for every G18 or G19 arc."""

from __future__ import annotations

from controller.blocks import PLANE_AXES, ArcBlock, HelixBlock, Source
from controller.interpreter.arcs import center_ijk, center_r
from controller.interpreter.codes import WordError
from controller.interpreter.modal import Modal

PLANE_NAMES = {170: "G17", 180: "G18", 190: "G19"}
# The centre offsets along the plane's first and second axis, then the one along its normal.
CENTRE_LETTERS = {"G17": ("I", "J", "K"), "G18": ("K", "I", "J"), "G19": ("J", "K", "I")}
_OFFSET_AXIS = {"I": 0, "J": 1, "K": 2}


def arc_block(modal: Modal, origin: tuple[float, float, float] | None, has_z: bool,
              config_name: str, clockwise: bool, end: tuple[float, float, float],
              vals: dict[str, float], source: Source) -> ArcBlock | HelixBlock:
    """The block of one G2/G3 from modal.pos to `end` (machine mm); WordError names the word
    at fault."""
    plane = PLANE_NAMES[modal.plane]
    a, b, n = PLANE_AXES[plane]
    first, second, normal = CENTRE_LETTERS[plane]
    motion = "G2" if clockwise else "G3"
    if plane != "G17" and not has_z:
        raise WordError(motion, f"{motion} in the {plane} plane needs a Z axis, and config "
                                f"'{config_name}' has none (select G17)")
    if vals.get(normal, 0.0) != 0.0:
        # LinuxCNC refuses any K in a G17 arc; grbl ignores it. K0 (FreeCAD's grbl post) says
        # nothing either would act on, so it is accepted; another value would be ignored
        # silently, so it is refused.
        raise WordError(normal, f"{normal} word in a {plane} arc: the centre offset along the "
                                f"plane's normal must be 0 or absent")
    start = modal.pos
    inch = modal.scale != 1.0
    s1, s2, e1, e2 = start[a], start[b], end[a], end[b]
    if "R" in vals:
        if first in vals or second in vals:
            raise WordError("R", f"arc with both R and {first} {second}: use one of them")
        c1, c2 = center_r(s1, s2, e1, e2, vals["R"] * modal.scale, clockwise, inch)
    elif first in vals or second in vals:
        c1, c2 = _centre(modal, origin, start, vals, (a, b), (first, second))
        center_ijk(s1, s2, e1, e2, c1, c2, inch, word=first if first in vals else second)
    else:
        raise WordError(motion, f"arc needs {first} {second} (centre) or R")
    turns = _turns(vals)
    if plane == "G17" and end[2] == start[2]:
        return ArcBlock(start, end, (c1, c2), clockwise, turns, modal.feed_mm_s,
                        modal.path_control, source)
    return HelixBlock(plane, start, end, (c1, c2), clockwise, turns, modal.feed_mm_s,
                      modal.path_control, source)


def _centre(modal: Modal, origin: tuple[float, float, float] | None,
            start: tuple[float, float, float], vals: dict[str, float], axes: tuple[int, int],
            letters: tuple[str, str]) -> tuple[float, float]:
    """The centre in machine mm: from the start (G91.1, LinuxCNC's default; a missing offset
    is 0, as there) or absolute in the work frame (G90.1: both offsets needed)."""
    out = []
    for axis, letter in zip(axes, letters, strict=True):
        if modal.arc_absolute:
            if letter not in vals:
                raise WordError(letter, f"{letter} word missing in absolute-centre arc (G90.1)")
            mm = vals[letter] * modal.scale
            out.append(mm if origin is None else mm + origin[axis])
        else:
            out.append(start[axis] + vals.get(letter, 0.0) * modal.scale)
    return out[0], out[1]


def _turns(vals: dict[str, float]) -> int:
    p = vals.get("P", 1.0)
    if p < 1 or p != int(p):
        raise WordError("P", "arc P (number of turns) must be a positive integer")
    return int(p) - 1
