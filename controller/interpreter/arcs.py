"""Arc centres for G2/G3 in the plane in force: centre offsets (incremental or absolute) or R,
with LinuxCNC's checks (interp_arc.cc). The coordinates are the plane's two axes, in machine mm:
(X, Y) in G17, (Z, X) in G18, (Y, Z) in G19."""

from __future__ import annotations

import math

from controller.interpreter.codes import WordError

MM_PER_INCH = 25.4
# LinuxCNC's tolerances (interp_internal.hh), given in program units and applied in mm here.
CENTER_ARC_RADIUS_TOLERANCE_MM = 2 * 0.01 * math.sqrt(2)
CENTER_ARC_RADIUS_TOLERANCE_INCH = 2 * 0.001 * math.sqrt(2)
RADIUS_TOLERANCE_MM = 0.00127
RADIUS_TOLERANCE_INCH = 0.00005
TOLERANCE_MM = 0.005
TOLERANCE_INCH = 0.0005
SPIRAL_RELATIVE_TOLERANCE = 0.001
_TINY = 1e-12
_TAU = 2 * math.pi
_HALF_PI = math.pi / 2


def _tol_mm(inch: bool, tol_mm: float, tol_inch: float) -> float:
    return tol_inch * MM_PER_INCH if inch else tol_mm


def center_ijk(sx: float, sy: float, ex: float, ey: float, cx: float, cy: float,
               inch: bool, word: str = "I") -> tuple[float, float]:
    """Check a centre-format arc whose centre (cx, cy) is already absolute mm; return it.

    LinuxCNC's rule (interp_arc.cc, arc_data_ijk): the end radius is refused only when it
    differs from the start radius by over 100 times the tolerance, or by over the tolerance
    and over 0.1 % of the larger radius. The tolerance is CENTER_ARC_RADIUS_TOLERANCE (2 *
    0.01 * sqrt(2) mm, 2 * 0.001 * sqrt(2) in; an INI setting there, fixed here): an arc whose
    end points and centre were rounded to 0.01 mm (0.001 in) is accepted."""
    r1 = math.hypot(sx - cx, sy - cy)
    r2 = math.hypot(ex - cx, ey - cy)
    if min(r1, r2) < _tol_mm(inch, RADIUS_TOLERANCE_MM, RADIUS_TOLERANCE_INCH):
        raise WordError(word, f"zero-radius arc: start radius {r1:.4f} mm, end radius {r2:.4f} mm")
    abs_err = abs(r1 - r2)
    rel_err = abs_err / max(r1, r2)
    abs_tol = _tol_mm(inch, CENTER_ARC_RADIUS_TOLERANCE_MM, CENTER_ARC_RADIUS_TOLERANCE_INCH)
    if abs_err > 100.0 * abs_tol or (abs_err > abs_tol and rel_err > SPIRAL_RELATIVE_TOLERANCE):
        raise WordError(word, f"radius to end of arc differs from radius to start: "
                             f"r1={r1:.4f} mm r2={r2:.4f} mm abs_err={abs_err:.4g} mm "
                             f"rel_err={rel_err * 100:.4f}%")
    return cx, cy


def center_r(sx: float, sy: float, ex: float, ey: float, radius_mm: float, clockwise: bool,
             inch: bool) -> tuple[float, float]:
    """Centre of an R-format arc; R < 0 asks for the arc longer than a semicircle."""
    if sx == ex and sy == ey:
        raise WordError("R", "R-format arc with end point equal to the current point "
                             "(a full circle needs I J)")
    abs_r = abs(radius_mm)
    if abs_r < _tol_mm(inch, RADIUS_TOLERANCE_MM, RADIUS_TOLERANCE_INCH):
        raise WordError("R", "zero-radius arc")
    mx, my = (sx + ex) / 2.0, (sy + ey) / 2.0
    half = math.hypot(mx - ex, my - ey)
    if half - abs_r > _tol_mm(inch, TOLERANCE_MM, TOLERANCE_INCH):
        raise WordError("R", f"arc radius {abs_r:.4f} mm too small to reach the end point "
                             f"({2 * half:.4f} mm away)")
    half = min(half, abs_r)  # allow a small error for a semicircle
    to_left = clockwise == (radius_mm < 0)
    theta = math.atan2(ey - sy, ex - sx) + (math.pi / 2 if to_left else -math.pi / 2)
    offset = math.sqrt(max(abs_r * abs_r - half * half, 0.0))
    return mx + offset * math.cos(theta), my + offset * math.sin(theta)


def arc_box(sx: float, sy: float, ex: float, ey: float, cx: float, cy: float, sweep_rad: float
            ) -> tuple[float, float, float, float]:
    """Axis-aligned box (xmin, ymin, xmax, ymax) of an arc of signed sweep from start."""
    r = math.hypot(sx - cx, sy - cy)
    a0 = math.atan2(sy - cy, sx - cx)
    lo, span = (a0, sweep_rad) if sweep_rad >= 0 else (a0 + sweep_rad, -sweep_rad)
    x0, x1 = (sx, ex) if sx < ex else (ex, sx)
    y0, y1 = (sy, ey) if sy < ey else (ey, sy)
    # The circle's axis extremes at 0, 90, 180, 270 degrees count if the arc passes them.
    if (-lo) % _TAU <= span:
        x1 = cx + r
    if (_HALF_PI - lo) % _TAU <= span:
        y1 = cy + r
    if (math.pi - lo) % _TAU <= span:
        x0 = cx - r
    if (3 * _HALF_PI - lo) % _TAU <= span:
        y0 = cy - r
    return x0, y0, x1, y1
