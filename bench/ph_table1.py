"""Table I analogue: PH error at the NACA 2415 leading edge without and with zone division (e=1 um).

The paper's airfoil has two corners (AB, CD); the shipped NACA 2415 NURBS (chord 30 mm) has one,
the leading edge, at kappa_th = 2450 / (3500/60)^2 = 0.720 /mm. Each row bisects the zone once
more; the paper's rule (divide until every piece's RMS <= e) stops at the first row that passes.
Run: python bench/ph_table1.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from controller.generator.corners.detection import detect_sharp_corners  # noqa: E402
from controller.generator.ph.fit import fit_zone, zone_fit_report  # noqa: E402
from controller.interpreter.program import program_nurbs  # noqa: E402

KAPPA_TH = 2450.0 / (3500.0 / 60.0) ** 2
E_MM = 1e-3


def main() -> None:
    curve = program_nurbs(str(REPO / "nc_programs" / "naca2415.nc"))[0]
    for zone in detect_sharp_corners(curve, KAPPA_TH):
        print(f"zone u {zone.u_start:.5f}..{zone.u_end:.5f}, peak kappa "
              f"{zone.kappa_peak_per_mm:.3f} /mm")
        print(f"{'pieces':>6}{'RMS um':>10}{'max um':>10}")
        for depth in range(4):
            pieces = fit_zone(curve, zone.u_start, zone.u_end, 0.0, max_depth=depth)
            rms = np.sqrt(np.mean([p.fit_rms_mm**2 for p in pieces])) * 1e3
            worst = max(p.fit_max_mm for p in pieces) * 1e3
            print(f"{len(pieces):>6}{rms:>10.3f}{worst:>10.3f}")
        r = zone_fit_report(curve, zone.u_start, zone.u_end, E_MM)
        print(f"Table I row: without division RMS {r.undivided_rms_mm * 1e3:.3f} max "
              f"{r.undivided_max_mm * 1e3:.3f} um; with division ({r.pieces} pieces, e = 1 um) "
              f"RMS {r.divided_rms_mm * 1e3:.3f} max {r.divided_max_mm * 1e3:.3f} um")


if __name__ == "__main__":
    main()
