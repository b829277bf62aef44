"""Planar PH quintic in complex form (eqs. 16-21): Hermite construction, closed-form arc length."""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from functools import lru_cache
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike

from controller.geometry.curves import curvature_derivative_from_derivatives
from controller.geometry.gauss_legendre import W64, X64
from controller.numeric import cached_property

_BINOM5 = np.array([1.0, 5.0, 10.0, 10.0, 5.0, 1.0])
_GL_X, _GL_W = X64, W64
_REAL_ROOT_TOL = 1e-12


def _xi(xi: ArrayLike) -> np.ndarray:
    return np.atleast_1d(np.asarray(xi, dtype=float))


@lru_cache(maxsize=16)
def _bernstein_to_power_matrix(n: int) -> np.ndarray:
    """M with power coefficients = M @ Bernstein coefficients, degree n."""
    m = np.zeros((n + 1, n + 1))
    for k in range(n + 1):
        for j in range(k, n + 1):  # B_k^n = C(n,k) sum_j C(n-k, j-k) (-1)^(j-k) x^j
            m[j, k] = math.comb(n, k) * math.comb(n - k, j - k) * (-1) ** (j - k)
    return m


def bernstein_to_power(b: np.ndarray) -> np.ndarray:
    """Power-basis coefficients (lowest first) of sum_k b_k B_k^n(x)."""
    return _bernstein_to_power_matrix(b.size - 1) @ b


def _horner(coeffs_low_first: tuple[float, ...] | tuple[complex, ...],
            x: np.ndarray) -> np.ndarray:
    acc = coeffs_low_first[-1] * x + coeffs_low_first[-2]
    for c in coeffs_low_first[-3::-1]:
        acc *= x
        acc += c
    return acc


def _sigma_values(w0: complex, w1: complex,
                  w2: complex) -> tuple[float, float, float, float, float]:
    """The Bernstein coefficients of |w|^2 (PhQuintic.sigma_values)."""
    return (abs(w0) ** 2, (w0 * w1.conjugate()).real,
            (2 * abs(w1) ** 2 + (w0 * w2.conjugate()).real) / 3,
            (w1 * w2.conjugate()).real, abs(w2) ** 2)


def _length_mm(sigma: tuple[float, float, float, float, float]) -> float:
    """sigma_bernstein.sum() / 5, in numpy's order for five values (one after the other)."""
    s0, s1, s2, s3, s4 = sigma
    return ((((s0 + s1) + s2) + s3) + s4) / 5.0


@dataclass(frozen=True)
class PhQuintic:
    """r(xi) = p0 + integral of w(xi)^2, w quadratic Bernstein with coefficients w0, w1, w2."""

    p0: complex
    w0: complex
    w1: complex
    w2: complex

    u_start = 0.0
    u_end = 1.0

    @classmethod
    def hermite(cls, p0: complex, p5: complex, d0: complex, d1: complex) -> PhQuintic:
        """The best of the 4 Hermite interpolants (docs/algorithms.md, PH quintic blends):
        canonical frame, minimum absolute rotation index, bending energy as tie-break, (+,+)
        first on full ties."""
        dp = p5 - p0
        if dp == 0:
            raise ValueError("PH Hermite data with coincident end points")
        candidates = _candidates(complex(p0), complex(dp), complex(d0), complex(d1))
        if _tame(d0 / dp) and _tame(d1 / dp):
            # Both end derivatives within 80 degrees of the chord and 0.5-2 chords long: the
            # canonical (+,+) solution is then the best (docs/algorithms.md, PH quintic blends;
            # checked by tests/geometry/test_ph_quintic.py), so skip ranking (root finding and
            # energy quadrature cost ~1 ms per corner blend).
            return candidates[0]
        return _best(candidates)

    # --- Bernstein data -------------------------------------------------------------------------
    def control_points(self) -> np.ndarray:
        """The 6 Bezier control points (complex)."""
        w0, w1, w2 = self.w0, self.w1, self.w2
        steps = [w0 * w0 / 5, w0 * w1 / 5, (2 * w1 * w1 + w0 * w2) / 15, w1 * w2 / 5, w2 * w2 / 5]
        return self.p0 + np.concatenate(([0j], np.cumsum(steps)))

    @classmethod
    def made(cls, p0: complex, w0: complex, w1: complex, w2: complex) -> PhQuintic:
        """PhQuintic(p0, w0, w1, w2) with its sigma values and length already in place, without
        the frozen setattr per field or a cached property's call for each (a G1 program makes
        one at every joint, and its length is asked at once)."""
        ph = object.__new__(cls)
        sigma = _sigma_values(w0, w1, w2)
        ph.__dict__.update(p0=p0, w0=w0, w1=w1, w2=w2, sigma_values=sigma,
                           length_mm=_length_mm(sigma))
        return ph

    @cached_property
    def sigma_values(self) -> tuple[float, float, float, float, float]:
        """sigma_bernstein as Python floats: a blend's length from them costs no numpy call
        (a G1 program has a blend at every joint)."""
        return _sigma_values(self.w0, self.w1, self.w2)

    @cached_property
    def sigma_bernstein(self) -> np.ndarray:
        """Bernstein coefficients of the parametric speed sigma = |w|^2 (quartic)."""
        return np.array(self.sigma_values)

    @cached_property
    def arc_length_bernstein(self) -> np.ndarray:
        """Bernstein coefficients of s(xi) (quintic): s_0 = 0, s_k = sum_{j<k} sigma_j / 5."""
        return np.concatenate(([0.0], np.cumsum(self.sigma_bernstein) / 5.0))

    # Power-basis coefficients as Python scalars: Horner on [0, 1] is well conditioned at degree 5
    # and Python scalars avoid numpy-scalar overhead in the interpolator's hot loop.
    @cached_property
    def _s_power(self) -> tuple[float, ...]:
        return tuple(float(c) for c in bernstein_to_power(self.arc_length_bernstein))

    @cached_property
    def _sigma_power(self) -> tuple[float, ...]:
        return tuple(float(c) for c in bernstein_to_power(self.sigma_bernstein))

    @cached_property
    def _r_power(self) -> tuple[complex, ...]:
        return tuple(complex(c) for c in bernstein_to_power(self.control_points()))

    @cached_property
    def length_mm(self) -> float:
        return _length_mm(self.sigma_values)

    @cached_property
    def arc_length_table(self) -> tuple[np.ndarray, np.ndarray]:
        """(xi, s(xi)) on 33 even nodes: the Newton starting guess of the interpolator."""
        xi = np.linspace(0.0, 1.0, 33)
        return xi, self.arc_length(xi)

    # --- evaluation (all vectorised over xi) -----------------------------------------------------
    def point(self, xi: ArrayLike) -> np.ndarray:
        return _horner(self._r_power, _xi(xi))

    def w(self, xi: ArrayLike) -> np.ndarray:
        x = _xi(xi)
        return self.w0 * (1 - x) ** 2 + 2 * self.w1 * (1 - x) * x + self.w2 * x * x

    def w_prime(self, xi: ArrayLike) -> np.ndarray:
        x = _xi(xi)
        return 2 * ((self.w1 - self.w0) * (1 - x) + (self.w2 - self.w1) * x)

    def hodograph(self, xi: ArrayLike) -> np.ndarray:
        return self.w(xi) ** 2

    def second_derivative(self, xi: ArrayLike) -> np.ndarray:
        return 2 * self.w(xi) * self.w_prime(xi)

    def third_derivative(self, xi: ArrayLike) -> np.ndarray:
        w2nd = 2 * (self.w0 - 2 * self.w1 + self.w2)
        return 2 * (self.w_prime(xi) ** 2 + self.w(xi) * w2nd)

    def sigma(self, xi: ArrayLike) -> np.ndarray:
        return _horner(self._sigma_power, _xi(xi))

    def arc_length(self, xi: ArrayLike) -> np.ndarray:
        return _horner(self._s_power, _xi(xi))

    def signed_curvature(self, xi: ArrayLike) -> np.ndarray:
        """kappa = 2 Im(conj(w) w') / |w|^4 (positive = turning left)."""
        w = self.w(xi)
        with np.errstate(divide="ignore", invalid="ignore"):
            return 2 * (w.conjugate() * self.w_prime(xi)).imag / np.abs(w) ** 4

    def curvature(self, xi: ArrayLike) -> np.ndarray:
        return np.abs(self.signed_curvature(xi))

    # --- the shared Curve interface --------------------------------------------------------------
    def evaluate(self, xi: ArrayLike, order: int = 2) -> np.ndarray:
        funcs = (self.point, self.hodograph, self.second_derivative, self.third_derivative)
        if order > 3:
            raise ValueError("PH quintic derivatives beyond the third are not provided")
        z = np.stack([f(xi) for f in funcs[: order + 1]])
        return np.stack((z.real, z.imag), axis=-1)

    def curvature_derivative(self, xi: ArrayLike) -> np.ndarray:
        return curvature_derivative_from_derivatives(self.evaluate(xi, 3))

    def s_of_u(self, xi: ArrayLike) -> np.ndarray:
        return self.arc_length(xi)

    def u_of_s(self, s_mm: ArrayLike, tol_mm: float = 1e-11) -> np.ndarray:
        return ph_interpolate(self, np.atleast_1d(np.asarray(s_mm, dtype=float)))[0]

    def derivatives_scalar(self, xi: float) -> tuple[float, float, float, float]:
        w = self.w0 * (1 - xi) ** 2 + 2 * self.w1 * (1 - xi) * xi + self.w2 * xi * xi
        dw = 2 * ((self.w1 - self.w0) * (1 - xi) + (self.w2 - self.w1) * xi)
        d1, d2 = w * w, 2 * w * dw
        return d1.real, d1.imag, d2.real, d2.imag

    # --- shape measures used to choose among the 4 interpolants ----------------------------------
    def absolute_rotation_index(self) -> float:
        """(1/2pi) * integral of |d theta|, theta = 2 arg w, split at inflections (exact)."""
        return _abs_rotation_index(self.w0, self.w1, self.w2)

    def bending_energy(self) -> float:
        """Integral of kappa^2 ds by 64-point Gauss-Legendre (inf at a zero-speed point)."""
        x = 0.5 * (_GL_X + 1.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            f = self.curvature(x) ** 2 * self.sigma(x)
        value = 0.5 * float(f @ _GL_W)
        return value if math.isfinite(value) else math.inf


TAME_ANGLE_RAD = math.radians(80.0)


def _tame(d_canonical: complex) -> bool:
    """An end derivative in the canonical frame within TAME_ANGLE_RAD of the chord and of a
    length comparable with it (longer ones make (+,+) loop: |d| = 5 |chord| did)."""
    return (0.5 <= abs(d_canonical) <= 2.0
            and abs(cmath.phase(d_canonical)) <= TAME_ANGLE_RAD)


def _candidates(p0: complex, dp: complex, d0: complex, d1: complex) -> list[PhQuintic]:
    """The 4 interpolants built in the canonical frame (p0 -> 0, p5 -> 1), mapped back."""
    d0c, d1c = d0 / dp, d1 / dp
    scale = cmath.sqrt(dp)
    out = []
    for e0, e2 in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        w0, w2 = e0 * cmath.sqrt(d0c), e2 * cmath.sqrt(d1c)
        w1 = -0.75 * (w0 + w2) + 0.25 * cmath.sqrt(120 - 15 * (w0 * w0 + w2 * w2) + 10 * w0 * w2)
        out.append(PhQuintic(p0, w0 * scale, w1 * scale, w2 * scale))
    return out


def _best(candidates: list[PhQuintic]) -> PhQuintic:
    """Least absolute rotation index (rounded so that equal ones tie), then least bending
    energy, then list order; the energy (a quadrature) only for the tied ones."""
    rot = [round(c.absolute_rotation_index(), 9) for c in candidates]
    tied = [c for c, r in zip(candidates, rot, strict=True) if r == min(rot)]
    if len(tied) == 1:
        return tied[0]
    return min(tied, key=lambda c: round(c.bending_energy(), 9))


def _quadratic_roots(a: complex, b: complex, c: complex) -> list[complex]:
    """Roots of a x^2 + b x + c in closed form, as np.roots gives them (a leading zero drops
    the degree), without its companion-matrix eigenvalues; the stable form avoids cancellation."""
    if a == 0:
        return [] if b == 0 else [-c / b]
    disc = cmath.sqrt(b * b - 4 * a * c)
    if (b.conjugate() * disc).real < 0:
        disc = -disc
    q = -0.5 * (b + disc)
    if q == 0:
        return [0j, 0j]
    return [q / a, c / q]


def _abs_rotation_index(w0: complex, w1: complex, w2: complex) -> float:
    """w = c (xi - z1)(xi - z2): d arg w / d xi = sum -Im z / |xi - z|^2, integrated piecewise."""
    lead, mid = w0 - 2 * w1 + w2, 2 * (w1 - w0)
    scale = max(abs(w0), abs(w1), abs(w2))
    if abs(lead) <= 1e-14 * scale:
        roots = [] if abs(mid) <= 1e-14 * scale else [-w0 / mid]
    else:
        roots = _quadratic_roots(lead, mid, w0)
    # A real root of w is a double root of r' = w^2: zero speed but no turning, so it drops out.
    roots = [z for z in roots if abs(z.imag) > _REAL_ROOT_TOL]
    cuts = [0.0, 1.0]
    if len(roots) == 2:  # inflections: b1((x-a2)^2+b2^2) + b2((x-a1)^2+b1^2) = 0
        (a1, b1), (a2, b2) = [(z.real, z.imag) for z in roots]
        quad = [b1 + b2, -2 * (b1 * a2 + b2 * a1), b1 * (a2**2 + b2**2) + b2 * (a1**2 + b1**2)]
        cuts += [r.real for r in _quadratic_roots(*(complex(q) for q in quad))
                 if abs(r.imag) < 1e-12 and 0 < r.real < 1]
    if not roots:
        return 0.0
    cuts.sort()  # at most four: plain Python floats are faster than numpy here
    theta = [sum(2 * math.atan2(-z.imag, c - z.real) for z in roots) for c in cuts]
    return sum(abs(b - a) for a, b in pairwise(theta)) / (2 * math.pi)


NEWTON_TOL_MM = 1e-9
NEWTON_SWEEPS = 3  # from the 33-node table start: ~1e-4 L -> ~1e-8 L -> ~1e-12 -> round-off
MAX_EXTRA_SWEEPS = 20


def _newton_sweep(ph: PhQuintic, xi: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Eq. 12 on the whole array, kept inside [0, 1]."""
    sigma = ph.sigma(xi)
    step = np.divide(ph.arc_length(xi) - s, sigma, out=np.zeros_like(xi), where=sigma > 0)
    return np.clip(xi - step, 0.0, 1.0)


def ph_interpolate(ph: PhQuintic, s_targets_mm: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Solve s(xi_k) = target_k for all k at once; returns (xi, |s(xi) - target| in mm).

    Start from linear interpolation in a coarse s(xi) table (s is monotone), then a fixed few
    vectorised Newton sweeps; extra sweeps only if some residual is still above 1e-9 mm.
    """
    s = np.clip(np.asarray(s_targets_mm, dtype=float), 0.0, ph.length_mm)
    table_xi, table_s = ph.arc_length_table
    xi = np.interp(s, table_s, table_xi)
    for _ in range(NEWTON_SWEEPS):
        xi = _newton_sweep(ph, xi, s)
    residual = np.abs(ph.arc_length(xi) - s)
    extra = 0
    while residual.size and residual.max() >= NEWTON_TOL_MM and extra < MAX_EXTRA_SWEEPS:
        xi, extra = _newton_sweep(ph, xi, s), extra + 1
        residual = np.abs(ph.arc_length(xi) - s)
    return xi, residual
