"""Time-optimal lower bound for the benchmark programs, from an independent B-spline evaluation."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline

from controller.generator.feed.time_bound import time_optimal_bound_s

REPO = Path(__file__).resolve().parents[1]
PROGRAMS = ("nc_programs/naca2415.nc", "nc_programs/butterfly.nc")
WORD = re.compile(r"([XYRKP])\s*([-+]?\d*\.?\d+)")


def read_g62(path: Path) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Order, control points (n,2), weights (n,) and knots of the first G6.2 NURBS in a file.

    Independent of the controller's interpreter on purpose (this is an oracle): control-point lines
    carry X Y R K, then the remaining knots come on `G6.2 K` lines.
    """
    order, pts, wts, knots = 0, [], [], []
    for raw in path.read_text().splitlines():
        line = raw.split("(")[0].strip().upper()
        words = dict(WORD.findall(line))
        if line.startswith("G6.2") and "P" in words:
            order = int(float(words["P"]))
        if not order:
            continue
        if "K" not in words:
            break  # the first line without a knot ends the NURBS block
        if "X" in words:
            pts.append((float(words["X"]), float(words["Y"])))
            wts.append(float(words.get("R", 1.0)))
        knots.append(float(words["K"]))
    return order, np.array(pts), np.array(wts), np.array(knots)


def arc_length_samples(path: Path, n: int = 40_000) -> tuple[np.ndarray, np.ndarray]:
    """Uniform arc-length grid s (n points) and the curvature there, via homogeneous BSplines."""
    order, pts, w, t = read_g62(path)
    hom = BSpline(t, np.column_stack([pts * w[:, None], w]), order - 1)
    d1, d2 = hom.derivative(1), hom.derivative(2)

    def geometry(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, h1, h2 = hom(u), d1(u), d2(u)
        c = h[:, :2] / h[:, 2:]
        c1 = (h1[:, :2] - h1[:, 2:] * c) / h[:, 2:]
        c2 = (h2[:, :2] - 2.0 * h1[:, 2:] * c1 - h2[:, 2:] * c) / h[:, 2:]
        speed = np.hypot(c1[:, 0], c1[:, 1])
        return speed, (c1[:, 0] * c2[:, 1] - c1[:, 1] * c2[:, 0]) / speed ** 3

    # Gauss-Legendre (8 nodes) on a fine split of every knot span gives s(u) to ~1e-12 mm.
    brk = np.unique(t[order - 1:len(t) - order + 1])
    edges = np.unique(np.concatenate([np.linspace(a, b, 65)
                                      for a, b in zip(brk[:-1], brk[1:], strict=True)]))
    x, gw = np.polynomial.legendre.leggauss(8)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    speed, _ = geometry((mid[:, None] + half[:, None] * x).ravel())
    s_edges = np.concatenate(([0.0], np.cumsum(half * (speed.reshape(-1, 8) @ gw))))
    s = np.linspace(0.0, s_edges[-1], n)
    u = np.interp(s, s_edges, edges)
    for _ in range(3):  # Newton on s(u) = s_target from the interpolated start
        spd, _ = geometry(u)
        seg = np.clip(np.searchsorted(edges, u) - 1, 0, len(edges) - 2)
        s_u = s_edges[seg] + _span_length(geometry, edges[seg], u)
        u = np.clip(u - (s_u - s) / spd, edges[0], edges[-1])
    return s, np.abs(geometry(u)[1])


def _span_length(geometry, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Arc length from a to b (elementwise), Gauss-Legendre 8 nodes."""
    x, gw = np.polynomial.legendre.leggauss(8)
    mid, half = 0.5 * (a + b), 0.5 * (b - a)
    speed, _ = geometry((mid[:, None] + half[:, None] * x).ravel())
    return half * (speed.reshape(-1, 8) @ gw)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("programs", nargs="*", default=[str(REPO / p) for p in PROGRAMS])
    ap.add_argument("--vmax", type=float, default=3500.0 / 60.0, help="mm/s")
    ap.add_argument("--amax", type=float, default=2450.0, help="mm/s^2")
    ap.add_argument("--period", type=float, default=0.001, help="s")
    ap.add_argument("--chord-tol", type=float, default=0.001, help="mm")
    args = ap.parse_args(argv)
    for prog in args.programs:
        s, kappa = arc_length_samples(Path(prog))
        bound = time_optimal_bound_s(s, kappa, args.vmax, args.amax, args.period, args.chord_tol)
        print(f"{Path(prog).name}: L = {s[-1]:.3f} mm, max kappa = {kappa.max():.2f} /mm, "
              f"T_min = {bound:.4f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
