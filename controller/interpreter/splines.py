"""G5.1 quadratic B-splines (LinuxCNC): one line, one quadratic Bezier as a NURBS block.

`G5.1 X Y I J` runs from the current point to X Y; I J is the control point's offset from the
start (program units, also under G91). The curve is the NURBS of order 3 with the control
points start, start + I J, end, weights 1 and knots 0 0 0 1 1 1: the block G5.2 L3 builds from
the same three points, planned by the same path.
"""

from __future__ import annotations

from controller.blocks import NurbsBlock, Source
from controller.interpreter.codes import WordError
from controller.interpreter.modal import Modal
from controller.interpreter.nurbs_blocks import NurbsCollector

_END_WORDS = ("X", "Y", "@", "^")


def quadratic_control(modal: Modal, vals: dict[str, float]) -> tuple[float, float]:
    """The control point (machine mm) of a G5.1 line, after LinuxCNC's checks of the line."""
    if modal.plane != 170:
        raise WordError("G5.1", "G5.1 splines run in the XY plane (G17) only")
    if "Z" in vals:
        raise WordError("Z", "G5.1 splines stay at constant Z: no Z word on a G5.1 line")
    if not any(word in vals for word in _END_WORDS):
        raise WordError("G5.1", "G5.1 needs its end point: X and Y (or @ and ^)")
    if "I" not in vals or "J" not in vals:
        raise WordError(
            "I" if "I" in vals else "J" if "J" in vals else "G5.1",
            "G5.1 needs both I and J: the control point's offset from the start",
        )
    x0, y0, _ = modal.pos
    control = (x0 + vals["I"] * modal.scale, y0 + vals["J"] * modal.scale)
    return control


def quadratic_block(
    start: tuple[float, float, float],
    control: tuple[float, float],
    end: tuple[float, float, float],
    modal: Modal,
    pulse_mm: float,
    max_feed_mm_s: float,
    source: Source,
) -> NurbsBlock:
    """The NURBS block of one G5.1 (the checks of a G5.2 block: length, near points)."""
    collector = NurbsCollector(
        "G5.1",
        3,
        start[0],
        start[1],
        1.0,
        start[2],
        modal.feed_mm_s,
        modal.path_control,
        source.path,
        source.first_line,
        pulse_mm,
    )
    collector.add_point(control[0], control[1], 1.0, source.first_line)
    collector.add_point(end[0], end[1], 1.0, source.first_line)
    return collector.finish(source.first_line, max_feed_mm_s)
