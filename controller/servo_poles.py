"""The closed-loop servo model's poles, checked when a config is read: stable, damped, sampled."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

MIN_DAMPING = 0.1  # a loop that rings longer than this is no machine to plan for
MIN_POLE_RAD_S = 1e-3  # slower than this the loop never settles in a job's time


def pole_problem(denominator: Sequence[float], sample_period_s: float) -> str | None:
    """Why the model whose denominator is [a4, a3, a2, a1, a0] (eq. 27: a4 s^4 + ... + a0) is
    unusable, naming its poles; None when it is fine."""
    with np.errstate(all="ignore"):
        p = np.roots(np.asarray(denominator, dtype=float))
    if len(p) == 0 or not np.all(np.isfinite(p)):
        return "its poles cannot be computed (coefficients out of range)"
    text = ", ".join(_pole_text(z) for z in sorted(p, key=lambda z: (z.real, z.imag)))
    if np.any(p.real >= 0):
        return f"unstable: poles {text} (rad/s) must all have a negative real part"
    damping = -p.real / np.abs(p)
    if damping.min() < MIN_DAMPING:
        return (f"damping {damping.min():.3f} below {MIN_DAMPING}: poles {text} (rad/s) ring "
                f"too long to plan for")
    nyquist_rad_s = math.pi / sample_period_s
    if np.abs(p).max() >= nyquist_rad_s:
        return (f"a pole faster than the sampling can represent: poles {text} (rad/s), "
                f"Nyquist {nyquist_rad_s:.0f} rad/s at T = {sample_period_s:g} s")
    if np.abs(p).min() < MIN_POLE_RAD_S:
        return f"a pole slower than {MIN_POLE_RAD_S:g} rad/s: poles {text} (rad/s)"
    return None


def _pole_text(z: complex) -> str:
    if abs(z.imag) < 1e-9 * max(1.0, abs(z)):
        return f"{z.real:.4g}"
    return f"{z.real:.4g}{z.imag:+.4g}j"
