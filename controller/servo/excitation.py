"""Excitation for identifying an axis's loop: a tapered random-phase multisine in position.

Why this signal: the eq. 27 loop is linear, so a sum of sines probes its error response at
chosen frequencies with all of them present at once, and the record can be split into a part
to fit and a part to check that see the same spectrum (a chirp would give the held-out part
only its top octave). The frequencies are spread logarithmically from a few Hz (where the
velocity lag c1 shows) to past the loop's fastest pole (where its dynamics show), with velocity
amplitudes falling as f^-1/2: at high frequency the error is the commanded motion itself (the
loop cannot follow), so less velocity there still gives errors well above a pulse, and the
acceleration, which grows as f^1/2, stays the limit that sets the scale. Several phase draws
are tried and the one with the lowest peak acceleration kept (the crest factor decides how
large the signal can be).

The multisine is multiplied by a quintic smoothstep envelope at both ends, so position,
velocity and acceleration all start and end at zero: the axis starts and ends at rest at its
start point. The scale is chosen so that |v| <= Vmax, |a| <= Amax and |x| <= the half window
hold for the whole signal and also for a fade-out begun at any sample (an operator's abort
ends the signal early with the same envelope: `fade_out`), using the triangle inequality on
the envelope's terms. Pure numpy, vectorised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_FREQUENCIES = 24
N_PHASE_DRAWS = 8
MARGIN = 0.9  # of Vmax and Amax: the quantisation to pulses adds a little to both
TAPER_S = 0.25  # envelope ramp at each end (and the length of an abort's fade-out)


@dataclass(frozen=True, eq=False)
class Excitation:
    """One axis's excitation, relative to its start point, one value per sample."""

    position_mm: np.ndarray  # x(k T), k = 1..n: zero at both ends
    sample_period_s: float
    peak_velocity_mm_s: float
    peak_accel_mm_s2: float
    # The raw multisine (before the envelope) and its derivatives: a fade-out needs them.
    raw_mm: np.ndarray
    raw_v_mm_s: np.ndarray
    frequencies_hz: np.ndarray

    @property
    def excursion_mm(self) -> tuple[float, float]:
        """(lowest, highest) position relative to the start, the fade-out's included."""
        return float(min(self.raw_mm.min(), 0.0) if len(self.raw_mm) else 0.0), \
            float(max(self.raw_mm.max(), 0.0) if len(self.raw_mm) else 0.0)

    def fade_out(self, k0: int) -> np.ndarray:
        """The positions from sample k0 on when the signal ends early: the envelope in force
        times a quintic ramp down over TAPER_S, ending at the start point at rest."""
        n = max(1, int(round(TAPER_S / self.sample_period_s)))
        k = np.arange(k0, min(k0 + n, len(self.position_mm)))
        if not len(k):
            return np.zeros(0)
        ramp = 1.0 - _smoothstep((k - k0 + 1) / n)[0]
        return self.position_mm[k] * ramp


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic 10u^3 - 15u^4 + 6u^5 clipped to [0, 1], with its first and second derivative
    in u: zero slope and curvature at both ends."""
    u = np.clip(u, 0.0, 1.0)
    w = u**3 * (10.0 - 15.0 * u + 6.0 * u**2)
    dw = 30.0 * u**2 * (1.0 - u) ** 2
    ddw = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return w, dw, ddw


def _envelope(t_s: np.ndarray, total_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Up over TAPER_S, flat, down over TAPER_S; derivatives in time."""
    up, dup, ddup = _smoothstep(t_s / TAPER_S)
    down, ddown, dddown = _smoothstep((total_s - t_s) / TAPER_S)
    w = up * down
    dw = (dup * down - up * ddown) / TAPER_S
    ddw = (ddup * down - 2.0 * dup * ddown + up * dddown) / TAPER_S**2
    return w, dw, ddw


def design(sample_period_s: float, vmax_mm_s: float, amax_mm_s2: float, half_window_mm: float,
           duration_s: float = 4.0, f_lo_hz: float = 2.0, f_hi_hz: float = 80.0,
           seed: int = 31) -> Excitation:
    """The excitation within Vmax, Amax and +-half_window_mm of the start (see the module).

    f_hi_hz is kept below a fifth of the sample rate (the ZOH frames of a faster sine are
    mostly steps). Raises ValueError on a limit that is not positive."""
    if not (sample_period_s > 0 and vmax_mm_s > 0 and amax_mm_s2 > 0 and half_window_mm > 0
            and duration_s > 2 * TAPER_S):
        raise ValueError("excitation limits must be positive (and the duration > 2 tapers)")
    f_hi = min(f_hi_hz, 0.2 / sample_period_s)
    f_lo = min(f_lo_hz, f_hi / 2.0)
    freqs = np.geomspace(f_lo, f_hi, N_FREQUENCIES)
    w_rad = 2.0 * np.pi * freqs
    v_amp = (freqs / f_lo) ** -0.75
    n = int(round(duration_s / sample_period_s))
    t = np.arange(1, n + 1) * sample_period_s
    env, denv, ddenv = _envelope(t, n * sample_period_s)
    rng = np.random.default_rng(seed)
    best: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
    for _ in range(N_PHASE_DRAWS):
        phase = rng.uniform(0.0, 2.0 * np.pi, N_FREQUENCIES)
        arg = np.outer(t, w_rad) + phase  # (n, K)
        x = np.sin(arg) @ (v_amp / w_rad)
        v = np.cos(arg) @ v_amp
        a = -np.sin(arg) @ (v_amp * w_rad)
        # Bounds for the signal under any envelope of this shape (the end taper or a fade
        # begun anywhere): |w x| <= |x|, |(w x)'| <= |w'| |x| + |v|, and likewise for a.
        dmax, ddmax = float(np.abs(denv).max()), float(np.abs(ddenv).max())
        xm, vm, am = (float(np.abs(s).max()) for s in (x, v, a))
        scale = min(MARGIN * vmax_mm_s / (dmax * xm + vm),
                    MARGIN * amax_mm_s2 / (ddmax * xm + 2.0 * dmax * vm + am),
                    half_window_mm / xm)
        if best is None or scale > best[0]:
            best = (scale, x, v, a)
    assert best is not None
    scale, x, v, a = best
    x, v, a = x * scale, v * scale, a * scale
    pos = env * x
    vel = denv * x + env * v
    acc = ddenv * x + 2.0 * denv * v + env * a
    return Excitation(position_mm=pos, sample_period_s=sample_period_s,
                      peak_velocity_mm_s=float(np.abs(vel).max()),
                      peak_accel_mm_s2=float(np.abs(acc).max()), raw_mm=x, raw_v_mm_s=v,
                      frequencies_hz=freqs)
