"""The second-order Taylor interpolator of NURBS (eq. 5) for the baselines; its feed fluctuation."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from controller.geometry.curves import Curve


def taylor_step(curve: Curve, u: float, v_mm_s: float, a_mm_s2: float, T_s: float) -> float:
    """Eq. 5: u + V T/|C'| + T^2/2 (A/|C'| - V^2 (C'.C'')/|C'|^4)."""
    dx, dy, ddx, ddy = curve.derivatives_scalar(u)
    speed2 = dx * dx + dy * dy
    speed = math.sqrt(speed2)
    return (u + v_mm_s * T_s / speed
            + 0.5 * T_s * T_s * (a_mm_s2 / speed - v_mm_s * v_mm_s * (dx * ddx + dy * ddy)
                                 / (speed2 * speed2)))


def taylor_interpolate(curve: Curve, u0: float, v_mm_s: ArrayLike, a_mm_s2: ArrayLike,
                       T_s: float) -> np.ndarray:
    """u_0 .. u_N for N ticks of eq. 5 (sequential by nature); u is held at the curve's end."""
    v = np.asarray(v_mm_s, dtype=float).tolist()
    a = np.asarray(a_mm_s2, dtype=float).tolist()
    u_end = curve.u_end
    out = [float(u0)]
    u = float(u0)
    for vk, ak in zip(v, a, strict=True):
        if u < u_end:
            u = min(taylor_step(curve, u, vk, ak, T_s), u_end)
        out.append(u)
    return np.array(out)


@dataclass(frozen=True, eq=False, repr=False)
class FeedFluctuation:
    """Per-step |actual step - V T| / (V T): maximum, RMS and the whole series."""

    max_ratio: float
    rms_ratio: float
    per_step: np.ndarray


def feed_fluctuation(points: ArrayLike, v_mm_s: ArrayLike, T_s: float) -> FeedFluctuation:
    """points: (N+1,) arc-length positions (exact step = difference) or (N+1, 2) positions
    (step = chord). v_mm_s: the commanded feed of each of the N steps (scalar or (N,))."""
    p = np.asarray(points, dtype=float)
    step = np.diff(p) if p.ndim == 1 else np.linalg.norm(np.diff(p, axis=0), axis=1)
    nominal = np.broadcast_to(np.asarray(v_mm_s, dtype=float), step.shape) * T_s
    ratio = np.abs(step - nominal) / nominal
    return FeedFluctuation(float(ratio.max()), float(np.sqrt(np.mean(ratio**2))), ratio)
