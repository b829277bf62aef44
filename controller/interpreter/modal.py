"""The modal state the parts of the interpreter share: position, units, distance modes, feed."""

from __future__ import annotations

from dataclasses import dataclass, field

from controller.blocks import PathControl


@dataclass(slots=True, eq=False)
class Modal:
    """What a line's motion and offset codes read and the next lines inherit.

    One instance is shared by InterpState (which sets the modes), Moves (which moves `pos`)
    and the work offset codes (which read `pos` and `scale`)."""

    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)  # machine mm
    scale: float = 1.0  # mm per program unit (G21 / G20)
    absolute: bool = True  # G90
    arc_absolute: bool = False  # G91.1 is LinuxCNC's default
    feed_mm_s: float = 0.0
    plane: int = 170  # code10 of G17 (XY), G18 (ZX) or G19 (YZ): the plane of G2/G3
    motion: int | None = None  # code10 of the modal motion; None after G80 / NURBS
    path_control: PathControl = field(default_factory=PathControl)
