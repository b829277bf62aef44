"""Test programs made on the fly: NACA 4-digit sections of any chord and random lobed NURBS."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.interpolate import make_lsq_spline


def naca_points(code: str, chord_mm: float, n: int = 200) -> np.ndarray:
    """Closed NACA 4-digit section, TE -> upper -> LE -> lower -> TE, TE at the origin."""
    m, p, t = int(code[0]) / 100, int(code[1]) / 10, int(code[2:]) / 100
    x = 0.5 * (1 - np.cos(np.linspace(0, np.pi, n)))
    yt = 5 * t * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3
                  - 0.1036 * x**4)
    if m > 0:
        yc = np.where(x < p, m / p**2 * (2 * p * x - x**2),
                      m / (1 - p) ** 2 * ((1 - 2 * p) + 2 * p * x - x**2))
        dyc = np.where(x < p, 2 * m / p**2 * (p - x), 2 * m / (1 - p) ** 2 * (p - x))
    else:
        yc, dyc = np.zeros_like(x), np.zeros_like(x)
    th = np.arctan(dyc)
    upper = np.column_stack([x - yt * np.sin(th), yc + yt * np.cos(th)])
    lower = np.column_stack([x + yt * np.sin(th), yc - yt * np.cos(th)])
    pts = np.vstack([upper[::-1], lower[1:]]) * chord_mm
    pts[:, 0] = -(pts[:, 0] - pts[0, 0])  # trailing edge at the origin, LE towards -X
    pts[:, 1] -= pts[0, 1]
    return pts


def naca_loop_points(code: str, chord_mm: float, start: int = 50, n: int = 200) -> np.ndarray:
    """The section as a closed loop through its trailing edge: from point `start` of the upper
    surface on (counted from the TE), round the LE and the TE back to it, moved to the origin."""
    pts = naca_points(code, chord_mm, n)[:-1]  # the TE once
    loop = np.vstack([pts[start:], pts[:start + 1]])
    return loop - loop[0]


def lsq_nurbs(points: np.ndarray, n_ctrl: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Cubic least-squares B-spline (centripetal parameters, quantile knots): (ctrl, knots)."""
    d = np.sqrt(np.linalg.norm(np.diff(points, axis=0), axis=1))
    u = np.concatenate([[0.0], np.cumsum(d)])
    u /= u[-1]  # exactly 1 at the end (dividing by d.sum() can round just past the last knot)
    inner = np.quantile(u[1:-1], np.linspace(0, 1, n_ctrl - 2)[1:-1])
    knots = np.r_[[0.0] * 4, inner, [1.0] * 4]
    spline = make_lsq_spline(u, points, knots, k=3)
    ctrl = spline.c.copy()
    ctrl[0], ctrl[-1] = points[0], points[-1]
    return ctrl, knots


def lobed_nurbs(seed: int, lobes: int = 5, n_ctrl: int = 24) -> tuple[np.ndarray, np.ndarray,
                                                                     np.ndarray]:
    """A random star-like cubic NURBS with sharp lobes: (ctrl, weights, knots), starts at 0,0."""
    rng = np.random.default_rng(seed)
    ang = np.linspace(0, 2 * np.pi, n_ctrl)
    r = 10.0 + 6.0 * (np.cos(lobes * ang) > 0.6) * rng.uniform(0.6, 1.0, n_ctrl)
    r += rng.uniform(-0.5, 0.5, n_ctrl)
    ctrl = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    ctrl -= ctrl[0]
    weights = rng.uniform(0.7, 2.5, n_ctrl)
    weights[0] = weights[-1] = 1.0
    inner = np.sort(rng.uniform(0.02, 0.98, n_ctrl - 4))
    knots = np.r_[[0.0] * 4, inner, [1.0] * 4]
    return ctrl, weights, knots


def write_g62(path: Path, ctrl: np.ndarray, knots: np.ndarray,
              weights: np.ndarray | None = None, feed_mm_min: float = 3500.0,
              comment: str | None = None) -> Path:
    """A G6.2 program (order 4) starting at X0 Y0, like the benchmark files."""
    w = np.ones(len(ctrl)) if weights is None else weights
    lines = [] if comment is None else [f"({comment})"]
    lines += ["G17 G21 G90", f"F{feed_mm_min:g}"]
    for i, (p, wi) in enumerate(zip(ctrl, w, strict=True)):
        head = "G6.2 P4 " if i == 0 else "     "
        lines.append(f"{head}X{p[0]:.6f} Y{p[1]:.6f} R{wi:.4f} K{knots[i]:.9f}")
    lines += [f"G6.2 K{k:.9f}" for k in knots[len(ctrl):]]
    lines += ["M2", ""]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def generated_program(folder: Path, name: str) -> Path:
    """A program by name: nacaCODE_CHORD (a section, e.g. naca0012_20) or lobed_SEED."""
    kind, arg = name.split("_")
    if kind.startswith("naca"):
        ctrl, knots = lsq_nurbs(naca_points(kind[4:], float(arg)))
        return write_g62(folder / f"{name}.nc", ctrl, knots)
    ctrl, weights, knots = lobed_nurbs(int(arg))
    return write_g62(folder / f"{name}.nc", ctrl, knots, weights)
