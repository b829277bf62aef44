"""What the look-ahead windows of one long program share: curves by content, their corners, blends.

CAM output repeats geometry (passes at several depths, the same contour again): each NURBS
block is interned by content, so its arc-length tables, corner zones, PH fits and feed-limit
samples are computed once per program and not once per copy, and a G1 corner between two
pieces of the same geometry is blended once. Only the windows of a long program use this
(plan.py): a program planned in one window is planned exactly as before, bit for bit, while
interning changes the order in which a curve's lazy tables are built, and so their last bits.

Bounded: at most MAX_CURVES curves, MAX_FITS PH fits and MAX_BLENDS blends are kept (the
oldest go first), so memory does not grow with the number of blocks; geometry that comes back
within about a hundred blocks is found again.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from controller.generator.corners.detection import CornerZone, detect_sharp_corners
from controller.generator.ph.construct import Blended, BlockCurve
from controller.geometry.nurbs import Nurbs
from controller.geometry.path import Piece, PieceKind
from controller.geometry.ph_quintic import PhQuintic

# Each entry holds its curve and the curve's lazy tables (about 80 kB for the airfoil): with
# 1000 distinct airfoils, 4096 fits and blends kept 75 MB of curves that never came back.
MAX_CURVES = 128
MAX_FITS = 256
MAX_BLENDS = 256
# A windowed run's G1 blends are searched to this relative precision of the cut instead of the
# 30 halvings of a single run: the cut is within 1 % of the largest that fits, in 2 trials at
# the airfoil's trailing edge where the 30 halvings take 31 (blend._searched).
BLEND_PRECISION = 0.01


class Bounded(OrderedDict):
    """A dict that forgets its oldest entries beyond `size`."""

    def __init__(self, size: int) -> None:
        super().__init__()
        self.size = size

    def __setitem__(self, key: Any, value: Any) -> None:
        super().__setitem__(key, value)
        if len(self) > self.size:
            self.popitem(last=False)


@dataclass(frozen=True, eq=False, repr=False)
class _Blend:
    """A blend by its geometry: the trimmed parameters and lengths, and the PH quintic."""

    u_a: float
    length_a_mm: float
    ph: PhQuintic
    u_b: float
    length_b_mm: float


class Repeats:
    """The caches one long program's windows share (see the module docstring)."""

    precision = BLEND_PRECISION

    def __init__(self) -> None:
        self.curves: Bounded = Bounded(MAX_CURVES)  # content -> [curve, corner zones or None]
        self.fits: Bounded = Bounded(MAX_FITS)  # construct.FitCache across windows
        self.blends: Bounded = Bounded(MAX_BLENDS)

    def intern(self, bc: BlockCurve) -> BlockCurve:
        """The block with the curve interned for its content (NURBS; other curves compare by
        value already)."""
        curve = bc.curve
        if not isinstance(curve, Nurbs):
            return bc
        key = (curve.degree, curve.knots.tobytes(), curve.control_points.tobytes(),
               curve.weights.tobytes())
        entry = self.curves.get(key)
        if entry is None:
            self.curves[key] = [curve, None]
            return bc
        return replace(bc, curve=entry[0])

    def corners(self, curve: Nurbs, kappa_th_per_mm: float) -> list[CornerZone]:
        """detect_sharp_corners of an interned curve, found once (a fresh list each time: the
        dynamics rounds widen zones in place)."""
        key = (curve.degree, curve.knots.tobytes(), curve.control_points.tobytes(),
               curve.weights.tobytes())
        entry = self.curves.get(key)
        if entry is None or entry[0] is not curve:
            return detect_sharp_corners(curve, kappa_th_per_mm)
        if entry[1] is None or entry[1][0] != kappa_th_per_mm:
            entry[1] = (kappa_th_per_mm, detect_sharp_corners(curve, kappa_th_per_mm))
        return list(entry[1][1])

    def blend(self, a: Piece, b: Piece, tol_mm: float, compute: Callable[[], Blended]) -> Blended:
        """The blend of a joint whose pieces have the geometry of one seen before (feed, line
        and corner taken from these pieces), else compute()."""
        key = (_geometry(a), _geometry(b), tol_mm)
        if key in self.blends:
            known = self.blends[key]
        else:
            found = compute()
            known = None if found is None else _Blend(
                found[0].u1, found[0].length_mm, found[1].curve,  # type: ignore[arg-type]
                found[2].u0, found[2].length_mm)
            self.blends[key] = known
            return found
        if known is None:
            return None
        return (Piece(a.kind, a.curve, a.u0, known.u_a, 0.0, known.length_a_mm, a.feed_mm_s,
                      a.line, a.corner),
                Piece(PieceKind.PH, known.ph, 0.0, 1.0, 0.0, known.ph.length_mm, b.feed_mm_s,
                      b.line),
                Piece(b.kind, b.curve, known.u_b, b.u1, 0.0, known.length_b_mm, b.feed_mm_s,
                      b.line, b.corner))


def _geometry(p: Piece) -> tuple:
    return (p.kind, p.curve, p.u0, p.u1, p.s0_mm, p.length_mm)
