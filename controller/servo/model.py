"""Servo-loop model of one axis (paper eq. 27, Table II), discretised at the sample period.

Convention (docs/algorithms.md, The servo model (eq. 27)): the tracking error E = R - P is the
output of the 4th-order E/V transfer function, zero-order-hold discretised, driven by the
per-sample axis velocity v[k] = (r[k] - r[k-1]) / T. With a0 = b0 the s factor of eq. 27 cancels, so
E/V = (s^3 + a3 s^2 + (a2 - b2) s + (a1 - b1)) / (s^4 + a3 s^3 + a2 s^2 + a1 s + a0)
(divided through by a4). This convention gives the steady ramp error V (a1 - b1) / a0.

Only numpy is used: scipy.signal costs 0.6 s to import, which `cncctl run` would pay before
the first motion. tests/servo/test_servo_model.py checks both functions against scipy.signal.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from controller.config import MachineConfig, ServoParams
from controller.numeric import cached_property

BLOCK = 256  # samples per block of the block-recursive filter


def error_transfer(p: ServoParams) -> tuple[np.ndarray, np.ndarray]:
    """Continuous E/V numerator and denominator (4th-order form, leading coefficient 1)."""
    if abs(p.a0 - p.b0) > 1e-9 * p.a0:
        # General case keeps the pole at s = 0 (eq. 27 as printed): E/V = (D - N) / (s D).
        num5 = np.array([p.a4, p.a3, p.a2 - p.b2, p.a1 - p.b1, p.a0 - p.b0]) / p.a4
        den5 = np.array([p.a4, p.a3, p.a2, p.a1, p.a0, 0.0]) / p.a4
        return num5, den5
    num = np.array([p.a4, p.a3, p.a2 - p.b2, p.a1 - p.b1]) / p.a4
    den = np.array([p.a4, p.a3, p.a2, p.a1, p.a0]) / p.a4
    return num, den


def expm(m: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring of a Taylor series (small, tame matrices)."""
    norm = float(np.abs(m).sum(axis=1).max())
    squarings = max(0, int(np.ceil(np.log2(norm / 0.25)))) if norm > 0.25 else 0
    a = m / 2.0**squarings
    term = np.eye(len(m))
    out = term.copy()
    for k in range(1, 20):
        term = term @ a / k
        out = out + term
    for _ in range(squarings):
        out = out @ out
    return out


def _companion(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, ...]:
    """Controllable canonical state space of a strictly proper num/den (den monic)."""
    n = len(den) - 1
    a = np.zeros((n, n))
    a[0, :] = -den[1:]
    a[1:, :-1] = np.eye(n - 1)
    b = np.zeros((n, 1))
    b[0, 0] = 1.0
    c = np.zeros((1, n))
    c[0, n - len(num):] = num
    return a, b, c


def zoh(num: np.ndarray, den: np.ndarray, sample_period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation of a strictly proper SISO transfer function -> (b, a)."""
    a_c, b_c, c_c = _companion(np.asarray(num, float), np.asarray(den, float))
    n = len(a_c)
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n:] = a_c, b_c
    e = expm(aug * sample_period_s)
    phi, gamma = e[:n, :n], e[:n, n:]
    a = np.real(np.poly(phi))
    # SISO identity: C (zI - Phi)^-1 Gamma = (det(zI - Phi + Gamma C) - det(zI - Phi)) / det(...)
    b = np.real(np.poly(phi - gamma @ c_c)) - a
    return b, a


@dataclass(frozen=True, eq=False, repr=False)
class DiscreteServo:
    """Discrete E/V filter coefficients (b, a) for one axis at period T."""

    b: np.ndarray
    a: np.ndarray
    sample_period_s: float

    @cached_property
    def _blocks(self) -> tuple[np.ndarray, ...]:
        """The block filter's matrices, built on the first filtering: most servos made while
        a model is composed (the pre-compensation's factors) are only read for b and a."""
        return _block_matrices(self.b, self.a, BLOCK)

    @property
    def order(self) -> int:
        return len(self.a) - 1

    @property
    def steady_lag_s(self) -> float:
        """Error per unit velocity at steady state: E = lag * V."""
        return float(np.sum(self.b) / np.sum(self.a))


def _block_matrices(b: np.ndarray, a: np.ndarray, n_block: int) -> tuple[np.ndarray, ...]:
    """State space (F, G, H, J) of b/a and its block form: y = O x + T u, x' = F^L x + R u,
    with all powers F^0..F^L kept for a partial block."""
    n = len(a) - 1
    bb = np.r_[b, np.zeros(len(a) - len(b))] if len(b) < len(a) else np.asarray(b, float)
    j = bb[0]
    f = np.zeros((n, n))
    f[0, :] = -a[1:]
    f[1:, :-1] = np.eye(n - 1)
    g = np.zeros(n)
    g[0] = 1.0
    h = bb[1:] - j * a[1:]
    powers = np.empty((n_block + 1, n, n))
    powers[0] = np.eye(n)
    for k in range(n_block):
        powers[k + 1] = f @ powers[k]
    obs = h @ powers[:n_block]  # (L, n): row k is h F^k
    impulse = np.r_[j, (obs[:n_block - 1] @ g)]  # h F^k g
    idx = np.arange(n_block)
    lag = idx[:, None] - idx[None, :]
    toeplitz = np.where(lag >= 0, impulse[np.clip(lag, 0, None)], 0.0)
    reach = (powers[n_block - 1::-1] @ g).T  # (n, L): column k is F^(L-1-k) g
    return obs, toeplitz, reach, powers


def filter_block(servo: DiscreteServo, u: np.ndarray, state: np.ndarray) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
    """Run the filter over u from state; vectorised in blocks of BLOCK samples. A block's
    Toeplitz product is written straight into the output and the free response added to it
    (the same sum); a whole block reads the whole matrices, not views cut to it."""
    out = np.empty(len(u))
    x = state.copy()
    for k0 in range(0, len(u), BLOCK):
        chunk = u[k0:k0 + BLOCK]
        obs, toeplitz, power, reach = _cut(servo, len(chunk))
        seg = out[k0:k0 + len(chunk)]
        np.matmul(toeplitz, chunk, out=seg)
        seg += obs @ x
        # After m samples: F^m x + sum_k F^(m-1-k) g u_k, the last m columns of the reach.
        x = power @ x + reach @ chunk
    return out, x


def _cut(servo: DiscreteServo, m: int) -> tuple[np.ndarray, ...]:
    """The block matrices for a block of m samples: (h F^k rows, Toeplitz, F^m, reach)."""
    obs, toeplitz, reach, powers = servo._blocks
    if m == BLOCK:
        return obs, toeplitz, powers[BLOCK], reach
    return obs[:m], toeplitz[:m, :m], powers[m], reach[:, BLOCK - m:]


def filter_state(servo: DiscreteServo, u: np.ndarray, state: np.ndarray) -> np.ndarray:
    """filter_block's state after u, the same numbers (the same products, block by block),
    without the outputs: their (BLOCK, BLOCK) product is most of a block's work."""
    x = state.copy()
    for k0 in range(0, len(u), BLOCK):
        chunk = u[k0:k0 + BLOCK]
        _, _, power, reach = _cut(servo, len(chunk))
        x = power @ x + reach @ chunk
    return x


def small_s_gains(servo: DiscreteServo) -> tuple[float, float]:
    """(c1, c2) of the filter's small-s expansion e ~ c1 v + c2 dv/dt (z^-1 = exp(-sT))."""
    b, a = servo.b, servo.a
    b_1, a_1 = float(b.sum()), float(a.sum())
    db = float(np.arange(len(b)) @ b)
    da = float(np.arange(len(a)) @ a)
    return b_1 / a_1, -servo.sample_period_s * (db * a_1 - b_1 * da) / a_1**2


@lru_cache(maxsize=64)
def discretise(p: ServoParams, sample_period_s: float) -> DiscreteServo:
    """Zero-order-hold discretisation of E/V at T (cached: the generator asks every round)."""
    num, den = error_transfer(p)
    b, a = zoh(num, den, sample_period_s)
    return DiscreteServo(b=b / a[0], a=a / a[0], sample_period_s=sample_period_s)


def tracking_error_mm(servo: DiscreteServo, v_mm_s: np.ndarray) -> np.ndarray:
    """Tracking error of an axis at rest at t = 0, for per-sample velocities (vectorised)."""
    return filter_block(servo, np.asarray(v_mm_s, dtype=float), np.zeros(servo.order))[0]


class AxisServoStepper:
    """Streaming form: feeds chunks of velocities and keeps the filter state between them."""

    def __init__(self, servo: DiscreteServo) -> None:
        self.servo = servo
        self.state = np.zeros(servo.order)

    def step(self, v_mm_s: np.ndarray) -> np.ndarray:
        """Tracking errors (mm) for the next chunk of per-sample velocities."""
        e, self.state = filter_block(self.servo, np.asarray(v_mm_s, float), self.state)
        return e


def contour_error_mm(ex_mm: np.ndarray, ey_mm: np.ndarray, phi_rad: np.ndarray) -> np.ndarray:
    """Eq. 28: eps = -Ex sin(phi) + Ey cos(phi), phi the path tangent angle."""
    return -ex_mm * np.sin(phi_rad) + ey_mm * np.cos(phi_rad)


def mismatched(p: ServoParams, pole_pct: float = 0.0, gain_pct: float = 0.0) -> ServoParams:
    """The same loop with every pole (and zero) moved by pole_pct (s -> s / k, k = 1 + pct:
    the bandwidth off, the DC gain kept), and its feed-forward falling short of the ideal by
    gain_pct more (a1 - b1 and a2 - b2, so the velocity and acceleration lags c1 and c2, scaled
    by 1 + pct). A real table is never its model: the sim card can run this plant while the
    planner keeps the nominal one."""
    k = 1.0 + pole_pct / 100.0
    g = 1.0 + gain_pct / 100.0
    if k <= 0.0 or g < 0.0:
        raise ValueError("mismatch must leave poles and gains positive")
    a1, a2, a3, a4 = p.a1 / k, p.a2 / k**2, p.a3 / k**3, p.a4 / k**4
    b1, b2 = p.b1 / k, p.b2 / k**2
    return ServoParams(a0=p.a0, a1=a1, a2=a2, a3=a3, a4=a4, b0=p.b0,
                       b1=a1 - (a1 - b1) * g, b2=a2 - (a2 - b2) * g)


def mismatched_config(config: MachineConfig, pole_pct: float = 0.0,
                      gain_pct: float = 0.0) -> MachineConfig:
    """The machine with every axis's servo mismatched alike (see mismatched)."""
    axes = tuple(replace(a, servo=mismatched(a.servo, pole_pct, gain_pct)) for a in config.axes)
    return replace(config, axes=axes)
