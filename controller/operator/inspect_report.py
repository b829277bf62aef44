"""What `cncctl inspect` reports: the NURBS blocks as the planner sees them (corners, PH fits)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

import numpy as np

from controller.blocks import ArcBlock, LineBlock, NcBlock, NurbsBlock
from controller.config import MachineConfig
from controller.generator.corners.detection import CornerZone, detect_sharp_corners
from controller.generator.ph.fit import PhSegment, fit_zone
from controller.geometry.nurbs import Nurbs


@dataclass(frozen=True)
class CornerInfo:
    u_start: float
    u_end: float
    u_peak: float
    kappa_peak_per_mm: float
    x: float
    y: float


@dataclass(frozen=True)
class PhInfo:
    u_start: float
    u_end: float
    length_mm: float
    fit_rms_um: float
    fit_max_um: float


@dataclass(frozen=True)
class NurbsInfo:
    line: int
    degree: int
    control_points: int
    length_mm: float
    sharp_corners: list[CornerInfo]
    ph_segments: list[PhInfo]


@dataclass
class InspectReport:
    """The JSON form of issue 3 item 5; curves/zones/segments are kept for the plot only."""

    path_length_mm: float = 0.0
    nurbs: list[NurbsInfo] = field(default_factory=list)
    curves: list[Nurbs] = field(default_factory=list)
    zones: list[list[CornerZone]] = field(default_factory=list)
    segments: list[list[PhSegment]] = field(default_factory=list)
    kappa_th_per_mm: list[float] = field(default_factory=list)
    # the lines and arcs as XY polylines (mm), each with True for a rapid: drawn, not reported
    moves: list[tuple[np.ndarray, bool]] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        return {"path_length_mm": self.path_length_mm, "nurbs": [asdict(n) for n in self.nurbs]}


def kappa_threshold_per_mm(block: NurbsBlock, config: MachineConfig) -> float:
    """Eq. 15 with V_max the block's feed (capped by the machine's maximum feed)."""
    ip = config.interpolator
    v_mm_s = min(block.feed_mm_s, ip.max_feed_mm_s)
    return ip.max_accel_mm_s2 / v_mm_s**2


def inspect_nurbs(curve: Nurbs, line: int, kappa_th_per_mm: float, error_limit_mm: float
                  ) -> tuple[NurbsInfo, list[CornerZone], list[PhSegment]]:
    """Corner zones of one NURBS and the PH chain replacing each zone."""
    zones = detect_sharp_corners(curve, kappa_th_per_mm)
    segments = [s for z in zones for s in fit_zone(curve, z.u_start, z.u_end, error_limit_mm)]
    peaks = curve.evaluate(np.array([z.u_peak for z in zones]), 0)[0] if zones else []
    corners = [CornerInfo(z.u_start, z.u_end, z.u_peak, z.kappa_peak_per_mm, float(p[0]),
                          float(p[1])) for z, p in zip(zones, peaks, strict=True)]
    phs = [PhInfo(s.u_start, s.u_end, s.ph.length_mm, s.fit_rms_mm * 1e3, s.fit_max_mm * 1e3)
           for s in segments]
    info = NurbsInfo(line, curve.degree, curve.control_points.shape[0], curve.length_mm,
                     corners, phs)
    return info, zones, segments


ARC_STEP_RAD = np.pi / 90  # 2 degrees a chord: a smooth arc at any plot size


def move_polyline(block: LineBlock | ArcBlock) -> np.ndarray:
    """The XY points (n, 2) of a line or arc, for the plot."""
    if isinstance(block, LineBlock):
        return np.array([block.start[:2], block.end[:2]], dtype=float)
    cx, cy = block.center
    sweep = block.sweep_rad
    t = np.linspace(0.0, 1.0, max(2, int(np.ceil(abs(sweep) / ARC_STEP_RAD)) + 1))
    a0 = np.arctan2(block.start[1] - cy, block.start[0] - cx)
    r_end = np.hypot(block.end[0] - cx, block.end[1] - cy)
    radius = block.radius_mm + (r_end - block.radius_mm) * t  # lands on the end point
    angle = a0 + sweep * t
    return np.column_stack([cx + radius * np.cos(angle), cy + radius * np.sin(angle)])


def inspect_blocks(blocks: Iterable[NcBlock], config: MachineConfig) -> InspectReport:
    """Walk the blocks: sum the path length, analyse every NURBS block."""
    report = InspectReport()
    for block in blocks:
        if isinstance(block, LineBlock | ArcBlock):
            report.path_length_mm += block.length_mm
            report.moves.append((move_polyline(block),
                                 isinstance(block, LineBlock) and block.rapid))
        elif isinstance(block, NurbsBlock):
            curve = Nurbs.from_block(block)
            kappa_th = kappa_threshold_per_mm(block, config)
            info, zones, segments = inspect_nurbs(curve, block.source.first_line, kappa_th,
                                                  config.interpolator.ph_error_limit_mm)
            report.path_length_mm += info.length_mm
            report.nurbs.append(info)
            report.curves.append(curve)
            report.zones.append(zones)
            report.segments.append(segments)
            report.kappa_th_per_mm.append(kappa_th)
    return report


def format_report(report: InspectReport) -> str:
    lines = [f"path length: {report.path_length_mm:.4f} mm, NURBS blocks: {len(report.nurbs)}"]
    for n in report.nurbs:
        lines.append(f"line {n.line}: NURBS degree {n.degree}, {n.control_points} control "
                     f"points, {n.length_mm:.4f} mm, {len(n.sharp_corners)} sharp corners")
        for c in n.sharp_corners:
            lines.append(f"  corner u {c.u_start:.5f}..{c.u_end:.5f} peak {c.u_peak:.5f} "
                         f"kappa {c.kappa_peak_per_mm:.3f} /mm at X{c.x:.4f} Y{c.y:.4f}")
        for s in n.ph_segments:
            lines.append(f"  PH u {s.u_start:.5f}..{s.u_end:.5f} {s.length_mm:.4f} mm, fit RMS "
                         f"{s.fit_rms_um:.3f} um, max {s.fit_max_um:.3f} um")
    return "\n".join(lines)
