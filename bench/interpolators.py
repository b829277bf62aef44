"""Bench: PH (Newton, vectorised) and 2nd-order Taylor interpolators on the butterfly at 58.33 mm/s.

What is measured
- Taylor: eq. 5 run tick by tick on the butterfly NURBS (scalar de Boor path). Its fluctuation is
  the exact arc length of each step (Gauss-Legendre table s(u)) against V*T.
- PH: the whole butterfly is replaced by a chain of PH quintics: every knot span is fitted with
  fit_zone (Hermite data from the NURBS, bisected until RMS error <= 1 um), so the chain follows
  the NURBS to 1 um and is G1. The constant feed F(kT) = k V T is cut at the segment joints and
  each segment's targets are solved in one vectorised ph_interpolate call. Its fluctuation is the
  closed-form arc length s(xi) of each step along the chain against V*T: what is left is the
  Newton tolerance (and the float rounding of the cumulative lengths).
Run: python bench/interpolators.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from controller.generator.ph.fit import PhSegment, fit_zone  # noqa: E402
from controller.geometry.nurbs import Nurbs  # noqa: E402
from controller.geometry.ph_quintic import ph_interpolate  # noqa: E402
from controller.geometry.taylor import feed_fluctuation, taylor_interpolate  # noqa: E402
from controller.interpreter.program import program_nurbs  # noqa: E402

V_MM_S = 58.33
T_S = 1e-3
E_MM = 1e-3


def ph_chain(curve: Nurbs) -> list[PhSegment]:
    spans = np.unique(curve.knots)
    return [seg for a, b in zip(spans[:-1], spans[1:], strict=True)
            for seg in fit_zone(curve, float(a), float(b), E_MM)]


def run_ph(chain: list[PhSegment]) -> tuple[float, np.ndarray, int, float]:
    """Returns (seconds, arc-length positions along the chain, points, max Newton residual)."""
    lengths = np.array([seg.ph.length_mm for seg in chain])
    offsets = np.concatenate(([0.0], np.cumsum(lengths)))
    targets = np.arange(0.0, offsets[-1], V_MM_S * T_S)
    owner = np.clip(np.searchsorted(offsets, targets, side="right") - 1, 0, len(chain) - 1)
    cuts = np.searchsorted(owner, np.arange(len(chain) + 1))
    positions = np.empty_like(targets)
    worst = 0.0
    t0 = time.perf_counter()
    for i, seg in enumerate(chain):
        lo, hi = cuts[i], cuts[i + 1]
        if lo == hi:
            continue
        xi, residual = ph_interpolate(seg.ph, targets[lo:hi] - offsets[i])
        positions[lo:hi] = offsets[i] + seg.ph.arc_length(xi)
        worst = max(worst, float(residual.max()))
    return time.perf_counter() - t0, positions, targets.size, worst


def run_taylor(curve: Nurbs) -> tuple[float, np.ndarray, int]:
    n = int(curve.length_mm / (V_MM_S * T_S)) - 1
    t0 = time.perf_counter()
    u = taylor_interpolate(curve, curve.u_start, np.full(n, V_MM_S), np.zeros(n), T_S)
    elapsed = time.perf_counter() - t0
    return elapsed, curve.s_of_u(u), n


def single_segment_rate(chain: list[PhSegment], points: int = 100_000) -> float:
    ph = max(chain, key=lambda s: s.ph.length_mm).ph
    targets = np.linspace(0.0, ph.length_mm, points)
    t0 = time.perf_counter()
    ph_interpolate(ph, targets)
    return (time.perf_counter() - t0) / points * 1e6


def main() -> None:
    curve = program_nurbs(str(REPO / "nc_programs" / "butterfly.nc"))[0]
    t0 = time.perf_counter()
    chain = ph_chain(curve)
    fit_s = time.perf_counter() - t0
    ph_s, ph_pos, ph_n, residual = run_ph(chain)  # cold: includes each PH's power-form setup
    warm_s = run_ph(chain)[0]
    ta_s, ta_pos, ta_n = run_taylor(curve)
    ph_ff = feed_fluctuation(ph_pos, V_MM_S, T_S)
    ta_ff = feed_fluctuation(ta_pos, V_MM_S, T_S)
    print(f"butterfly: NURBS length {curve.length_mm:.4f} mm; PH chain of {len(chain)} quintics "
          f"(fit {fit_s:.2f} s), length {sum(s.ph.length_mm for s in chain):.4f} mm, "
          f"worst fit RMS {max(s.fit_rms_mm for s in chain) * 1e3:.3f} um")
    print(f"feed {V_MM_S} mm/s, T = {T_S * 1e3:g} ms")
    print(f"{'interpolator':<28}{'points':>8}{'us/point':>10}{'max fluct':>12}{'rms fluct':>12}")
    print(f"{'PH Newton (per seg., cold)':<28}{ph_n:>8}{ph_s / ph_n * 1e6:>10.2f}"
          f"{ph_ff.max_ratio:>12.2e}{ph_ff.rms_ratio:>12.2e}")
    print(f"{'PH Newton (per seg., warm)':<28}{ph_n:>8}{warm_s / ph_n * 1e6:>10.2f}")
    print(f"{'PH Newton (one array)':<28}{100000:>8}{single_segment_rate(chain):>10.2f}"
          f"{'':>12}{'':>12}")
    print(f"{'Taylor 2nd order (eq. 5)':<28}{ta_n:>8}{ta_s / ta_n * 1e6:>10.2f}"
          f"{ta_ff.max_ratio:>12.2e}{ta_ff.rms_ratio:>12.2e}")
    print(f"PH max Newton residual {residual:.1e} mm")


if __name__ == "__main__":
    main()
