"""Modules 1 and 2 of the generator: sharp corner detection and PH construction for one run."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.blocks import ArcBlock, LineBlock, MotionBlock, NurbsBlock, PathMode
from controller.generator.corners.detection import (
    CornerZone,
    detect_sharp_corners,
    joint_angle_rad,
    widen_zone,
)
from controller.generator.ph.blend import blend_joint
from controller.generator.ph.fit import PhSegment, fit_zones
from controller.generator.ph.line_blends import (
    LineJoints,
    applies,
    blend_line_run,
    blend_lines,
    line_joints,
)
from controller.geometry.curves import ArcCurve, Curve, LineCurve
from controller.geometry.nurbs import Nurbs
from controller.geometry.path import Path, Piece, PieceKind, chain, end_tangent, make_piece

# Joints whose tangents turn by less than this are treated as smooth (CAM output jitter).
SMOOTH_JOINT_RAD = math.radians(0.5)
MIN_LENGTH_MM = 1e-6


@dataclass(frozen=True, eq=False, repr=False)
class BlockCurve:
    """One motion block as a curve, with its programmed feed and source line."""

    curve: Curve
    feed_mm_s: float
    line: int
    nurbs: bool
    blend_tolerance_mm: float | None = None  # how far a G1 corner at its end may be rounded


@dataclass(frozen=True, eq=False)
class CornerInfo:
    """A sharp corner found on block `block` (eq. 13-15) and how it was replaced."""

    block: int
    zone: CornerZone
    ph_count: int
    fit_rms_mm: float
    fit_max_mm: float
    x_mm: float
    y_mm: float


@dataclass(frozen=True, eq=False, repr=False)
class Geometry:
    """The output of modules 1-2: the path with PH corners, and what was done to it."""

    path: Path
    corners: tuple[CornerInfo, ...]
    ph_pieces: tuple[Piece, ...]
    g1_blends: int = 0


def block_curve(block: MotionBlock, feed_cap_mm_s: float,
                default_tolerance_mm: float = 0.0) -> BlockCurve | None:
    """The XY curve of a block, or None for a block that does not move in XY.

    Under G64 a G1 corner at the block's end may be rounded by G64 P, or by default_tolerance_mm
    (the contour error limit) when P is not given; under G61/G61.1 it is an exact stop."""
    feed = min(block.feed_mm_s, feed_cap_mm_s)
    line = block.source.first_line
    tol = None
    if block.path.mode == PathMode.BLEND:
        tol = block.path.tolerance_mm if block.path.tolerance_mm is not None \
            else default_tolerance_mm
    if isinstance(block, LineBlock):  # first: every G1 line of a program comes here
        p0, p1 = block.start[:2], block.end[:2]
        length = math.hypot(p1[0] - p0[0], p1[1] - p0[1])  # LineCurve.length_mm's
        if length < MIN_LENGTH_MM:
            return None
        # LineCurve(p0, p1) and BlockCurve(...) without the frozen setattr per field.
        curve = object.__new__(LineCurve)
        curve.__dict__.update(p0=p0, p1=p1, length_mm=length)
        bc = object.__new__(BlockCurve)
        bc.__dict__.update(curve=curve, feed_mm_s=feed, line=line, nurbs=False,
                           blend_tolerance_mm=tol)
        return bc
    if isinstance(block, NurbsBlock):
        if block.polygon_length_mm < MIN_LENGTH_MM:  # the curve is no longer than this
            return None
        return BlockCurve(Nurbs.from_block(block), feed, line, True, tol)
    assert isinstance(block, ArcBlock)
    c = block.center
    a0 = math.atan2(block.start[1] - c[1], block.start[0] - c[0])
    # The end radius may differ from the start radius (LinuxCNC's rule): a spiral to the
    # programmed end, not a circle that misses it.
    change = block.radius_change_mm
    return BlockCurve(ArcCurve(c, block.radius_mm, a0, block.sweep_rad, change), feed, line,
                      False, tol)


def block_curves(blocks: list[MotionBlock], feed_cap_mm_s: float,
                 default_tolerance_mm: float = 0.0) -> list[BlockCurve]:
    """block_curve of every block, the blocks that do not move in XY left out. A G1 line's
    curve is made here in one loop (the same fields as block_curve: 2 us less a line), its
    tolerance found again only when its path control is another object than the line
    before's (the interpreter hands the same one on from line to line)."""
    out: list[BlockCurve] = []
    new, line_block, blend = object.__new__, LineBlock, PathMode.BLEND
    path, tol = None, None
    for block in blocks:
        if type(block) is not line_block:
            if (bc := block_curve(block, feed_cap_mm_s, default_tolerance_mm)) is not None:
                out.append(bc)
            continue
        if block.path is not path:
            path = block.path
            tol = (path.tolerance_mm if path.tolerance_mm is not None
                   else default_tolerance_mm) if path.mode == blend else None
        p0, p1 = block.start[:2], block.end[:2]
        length = math.hypot(p1[0] - p0[0], p1[1] - p0[1])  # LineCurve.length_mm's
        if length < MIN_LENGTH_MM:
            continue
        curve = new(LineCurve)
        curve.__dict__.update(p0=p0, p1=p1, length_mm=length)
        bc = new(BlockCurve)
        feed = block.feed_mm_s  # min(feed, cap), which returns the first of equals
        bc.__dict__.update(curve=curve, feed_mm_s=feed_cap_mm_s if feed_cap_mm_s < feed else feed,
                           line=block.source.first_line, nurbs=False, blend_tolerance_mm=tol)
        out.append(bc)
    return out


def find_corners(curves: list[BlockCurve], kappa_th_per_mm: float) -> dict[int, list[CornerZone]]:
    """Module 1: curvature peaks above kappa_th with their zones, for every NURBS block."""
    return {i: detect_sharp_corners(bc.curve, kappa_th_per_mm)
            for i, bc in enumerate(curves) if bc.nurbs}


def widen(curves: list[BlockCurve], zones: dict[int, list[CornerZone]], block: int,
          u: float, level_per_mm: float) -> bool:
    """Widen the zone of `block` nearest to u down to curvature level; True if it grew."""
    blocks_zones = zones.get(block, [])
    if not blocks_zones:
        return False
    i = int(np.argmin([min(abs(u - z.u_start), abs(u - z.u_end)) for z in blocks_zones]))
    old = blocks_zones[i]
    new = widen_zone(curves[block].curve, old, level_per_mm)
    # Never let two zones of one block overlap: clip at the neighbours.
    lo = blocks_zones[i - 1].u_end if i > 0 else new.u_start
    hi = blocks_zones[i + 1].u_start if i + 1 < len(blocks_zones) else new.u_end
    new = CornerZone(max(new.u_start, lo), min(new.u_end, hi), new.u_peak, new.kappa_peak_per_mm)
    grew = new.u_start < old.u_start - 1e-12 or new.u_end > old.u_end + 1e-12
    blocks_zones[i] = new
    return grew


# Keyed by the curve itself, not id(curve): an id is only unique among live objects.
FitCache = dict[tuple[Curve, float, float, float], list[PhSegment]]


def _fits(curve: Curve, zones: list[CornerZone], error_limit_mm: float,
          cache: FitCache) -> list[list[PhSegment]]:
    """The PH fit of every zone, the ones not in the cache fitted together in one batch."""
    keys = [(curve, z.u_start, z.u_end, error_limit_mm) for z in zones]
    missing = [i for i, k in enumerate(keys) if k not in cache]
    if missing:
        fitted = fit_zones(curve, [(zones[i].u_start, zones[i].u_end) for i in missing],
                           error_limit_mm)
        for i, segs in zip(missing, fitted, strict=True):
            cache[keys[i]] = segs
    return [cache[k] for k in keys]


def _nurbs_pieces(bc: BlockCurve, block: int, zones: list[CornerZone], error_limit_mm: float,
                  use_ph: bool, corner_base: int,
                  cache: FitCache) -> tuple[list[Piece], list[CornerInfo]]:
    """Split one NURBS into Taylor parts and PH corners (module 2)."""
    curve = bc.curve
    # In path order: NURBS spans as (u0, u1, corner or -1), corner zones as their PH fits.
    spans: list[tuple[float, float, int] | list[PhSegment]] = []
    infos: list[CornerInfo] = []
    fits = _fits(curve, zones, error_limit_mm, cache) if use_ph and zones else []
    peaks = curve.evaluate(np.array([z.u_peak for z in zones]), 0)[0] if zones else []
    u = curve.u_start
    for k, z in enumerate(zones):
        if z.u_start > u + 1e-12:
            spans.append((u, z.u_start, -1))
        peak = peaks[k]
        if use_ph:
            segs = fits[k]
            spans.append(segs)
            rms = float(np.sqrt(np.mean([s.fit_rms_mm**2 for s in segs])))
            worst = max(s.fit_max_mm for s in segs)
            infos.append(CornerInfo(block, z, len(segs), rms, worst, float(peak[0]),
                                    float(peak[1])))
        else:
            spans.append((z.u_start, z.u_end, corner_base + k))
            infos.append(CornerInfo(block, z, 0, 0.0, 0.0, float(peak[0]), float(peak[1])))
        u = z.u_end
    if curve.u_end > u + 1e-12:
        spans.append((u, curve.u_end, -1))
    return _materialise(bc, spans, corner_base), infos


def _materialise(bc: BlockCurve, spans: list, corner_base: int) -> list[Piece]:
    """Pieces from _nurbs_pieces' spans, every NURBS span's length from one arc-length call."""
    ends = [u for sp in spans if isinstance(sp, tuple) for u in sp[:2]]
    s = bc.curve.s_of_u(np.array(ends)) if ends else np.empty(0)
    pieces: list[Piece] = []
    j, corner = 0, corner_base
    for sp in spans:
        if isinstance(sp, tuple):
            u0, u1, c = sp
            pieces.append(Piece(PieceKind.NURBS, bc.curve, u0, u1, 0.0, float(s[j + 1] - s[j]),
                                bc.feed_mm_s, bc.line, c))
            j += 2
        else:
            pieces += [Piece(PieceKind.PH, seg.ph, 0.0, 1.0, 0.0, seg.ph.length_mm,
                             bc.feed_mm_s, bc.line, corner) for seg in sp]
        if not isinstance(sp, tuple) or sp[2] >= 0:
            corner += 1
    return pieces


# A joint's blend by what it depends on: both pieces (curve, parameters, offset, length) and the
# tolerance. The dynamics rounds rebuild the path, mostly with the same joints: a round then
# reuses the blends (the same objects, so the same numbers) instead of fitting them again.
Blended = tuple[Piece, Piece, Piece] | None
BlendCache = dict[tuple, Blended]


def _piece_key(p: Piece) -> tuple:
    return (p.kind, p.curve, p.u0, p.u1, p.s0_mm, p.length_mm, p.feed_mm_s, p.line, p.corner)


def _blend(a: Piece, b: Piece, tol: float, cache: BlendCache | None,
           repeats: Any = None, line_row: tuple[LineJoints, int] | None = None) -> Blended:
    """blend_joint, remembered by the run (cache) and, for a long program's windows, by the
    geometry of the joint across windows (repeats: generator/repeats.py); a window's joint of
    two lines by its unit blend (line_row: line_blends.py)."""
    if line_row is not None:  # a few microseconds: not worth a key of both pieces
        return blend_lines(a, b, tol, *line_row)
    if cache is None:
        return blend_joint(a, b, tol)
    key = (_piece_key(a), _piece_key(b), tol)
    if key not in cache:
        if repeats is None:
            cache[key] = blend_joint(a, b, tol)
        else:
            cache[key] = repeats.blend(a, b, tol,
                                       lambda: blend_joint(a, b, tol, repeats.precision))
    return cache[key]


def _joint_angle_rad(a: Piece, b: Piece, line_row: tuple[LineJoints, int] | None) -> float:
    if line_row is not None:
        return line_row[0].angle_rad[line_row[1]]
    return joint_angle_rad(end_tangent(a, True), end_tangent(b, False))


def build_path(curves: list[BlockCurve], zones: dict[int, list[CornerZone]],
               error_limit_mm: float, use_ph: bool = True,
               cache: FitCache | None = None, prefix: tuple[Piece, ...] = (),
               prefix_tolerance_mm: float | None = None,
               blend_cache: BlendCache | None = None, repeats: Any = None) -> Geometry:
    """Module 2: the run's path, corner zones replaced by PH quintics within error_limit_mm.

    Joints between blocks whose tangents turn by more than SMOOTH_JOINT_RAD are G1 corners: a
    PH quintic blend within the block's tolerance (gen_blend), else an exact stop (feed zero).
    A prefix is geometry already decided by the previous look-ahead window; the blocks follow it.
    repeats, for the windows of a long program, shares blends across them (repeats.py).
    """
    cache = {} if cache is None else cache
    pieces: list[Piece] = list(prefix)
    # Per piece: made here for this path alone (chain may move it in place): the lines and arcs
    # and the G1 blends, not the prefix, the NURBS parts or blends a cache may hand out again.
    own = [False] * len(pieces)
    corner_base = max((p.corner for p in prefix), default=-1) + 1  # keep corner ids distinct
    infos: list[CornerInfo] = []
    stops: list[int] = []
    blends = 0
    joints = line_joints(curves) if repeats is not None else None
    i = 0
    while i < len(curves):
        if joints is not None and pieces:
            after = blend_line_run(pieces, own, curves, i, joints, SMOOTH_JOINT_RAD)
            blends += after - i
            if after == len(curves):
                break
            i = after
        bc = curves[i]
        if bc.nurbs:
            ps, inf = _nurbs_pieces(bc, i, zones.get(i, []), error_limit_mm, use_ph,
                                    corner_base + len(infos), cache)
            infos += inf
            mine = False
        else:
            kind = PieceKind.ARC if isinstance(bc.curve, ArcCurve) else PieceKind.LINE
            ps = [make_piece(kind, bc.curve, 0.0, 1.0, 0.0, bc.feed_mm_s, bc.line)]
            mine = True
        row = None if joints is None or not pieces else joints.row.get(i)
        line_row = None if row is None or not applies(pieces[-1], ps[0], joints, row) \
            else (joints, row)
        first_own = mine
        if pieces and _joint_angle_rad(pieces[-1], ps[0], line_row) > SMOOTH_JOINT_RAD:
            tol = curves[i - 1].blend_tolerance_mm if i > 0 else prefix_tolerance_mm
            blended = _blend(pieces[-1], ps[0], tol, blend_cache, repeats, line_row) \
                if tol else None
            if blended is None:
                stops.append(len(pieces))
            else:
                made = line_row is not None  # blend_lines' pieces are new; a cache's are not
                pieces[-1] = blended[0]
                own[-1] = made
                pieces.append(blended[1])
                own.append(made)
                ps[0] = blended[2]
                first_own = made
                blends += 1
        pieces += ps
        own += [first_own] + [mine] * (len(ps) - 1)
        i += 1
    chained = chain(pieces, own)
    stop_s = tuple(chained[k].s0_mm for k in stops)
    ph = tuple(p for p in chained if p.kind == PieceKind.PH)
    return Geometry(Path(chained, stop_s), tuple(infos), ph, blends)
