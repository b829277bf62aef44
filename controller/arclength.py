"""Arc length s(u) of a parametric curve by composite Gauss-Legendre, vectorised inverse u(s)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

SpeedFn = Callable[[np.ndarray], np.ndarray]  # |C'(u)| for an array of u
DerivsFn = Callable[[np.ndarray], np.ndarray]  # [C, C', C''] (3, N, 2) for an array of u

_GL_ORDER = 10
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_GL_ORDER)
_NEWTON_SWEEPS = 60  # safeguarded: usually 1-2 sweeps, bisection at worst
_NEWTON_TOL_MM = 1e-11
# The inverse table's cubic Hermite u(s) is checked to this at every sub-interval's midpoint.
# 1e-9 mm of position along the path is 1e-3 mm/s^2 of acceleration at T = 1 ms: far below what
# any check sees, so the generator's interpolation needs no Newton step at all.
INVERSE_TOL_MM = 1e-11
_INVERSE_PASSES = 6


def _gauss_integrals(speed: SpeedFn, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Integral of speed over each [a_i, b_i], all intervals in one speed call."""
    half = 0.5 * (b - a)
    nodes = (0.5 * (a + b))[:, None] + half[:, None] * _GL_X[None, :]
    values = speed(nodes.ravel()).reshape(nodes.shape)
    return half * (values @ _GL_W)


def _subdivide(breaks: np.ndarray, m: int) -> np.ndarray:
    """Split every non-empty interval between breakpoints into m equal parts."""
    lo, hi = breaks[:-1], breaks[1:]
    keep = hi > lo
    frac = np.arange(m) / m
    inner = (lo[keep][:, None] + (hi[keep] - lo[keep])[:, None] * frac[None, :]).ravel()
    return np.append(inner, breaks[-1])


@dataclass(frozen=True, eq=False)
class ArcLengthTable:
    """Cumulative arc length at sub-interval nodes; s(u) and u(s) evaluated to ~1e-12 relative."""

    speed: SpeedFn
    u_nodes: np.ndarray  # sub-interval boundaries
    s_nodes: np.ndarray  # arc length at u_nodes, s_nodes[0] = 0
    derivs: DerivsFn | None = None  # for the inverse table (u_of_s)

    @classmethod
    def build(cls, speed: SpeedFn, breaks: ArrayLike, rel_tol: float = 1e-12,
              derivs: DerivsFn | None = None) -> ArcLengthTable:
        """Double the sub-intervals per knot span until two successive totals agree to rel_tol."""
        brk = np.unique(np.asarray(breaks, dtype=float))
        m, previous = 2, None
        while True:
            u_nodes = _subdivide(brk, m)
            pieces = _gauss_integrals(speed, u_nodes[:-1], u_nodes[1:])
            total = float(pieces.sum())
            if previous is not None and abs(total - previous) <= rel_tol * max(total, 1e-300):
                break
            if m >= 1024:
                break
            previous, m = total, m * 2
        return cls(speed, u_nodes, np.concatenate(([0.0], np.cumsum(pieces))), derivs)

    @property
    def total_length_mm(self) -> float:
        return float(self.s_nodes[-1])

    def _interval(self, u: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(self.u_nodes, u, side="right") - 1
        return np.clip(idx, 0, self.u_nodes.size - 2)

    def s_of_u(self, u: ArrayLike) -> np.ndarray:
        """Arc length from the curve start to u (Gauss-Legendre on [u_node, u])."""
        uu = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), self.u_nodes[0], self.u_nodes[-1])
        idx = self._interval(uu)
        return self.s_nodes[idx] + _gauss_integrals(self.speed, self.u_nodes[idx], uu)

    @cached_property
    def _inverse(self) -> _InverseTable:
        if self.derivs is None:
            raise ValueError("an inverse table needs the curve's derivatives")
        return _InverseTable.build(self.speed, self.derivs, self.u_nodes, self.s_nodes)

    def u_of_s(self, s_mm: ArrayLike, tol_mm: float = _NEWTON_TOL_MM) -> np.ndarray:
        """Inverse: cubic Hermite on the inverse table (du/ds = 1/speed at its nodes), then, when
        tol_mm is below the table's INVERSE_TOL_MM, safeguarded Newton (bisection when a step
        leaves the bracket) to tol_mm."""
        s = np.clip(np.atleast_1d(np.asarray(s_mm, dtype=float)), 0.0, self.total_length_mm)
        inv = self._inverse
        u, idx = inv.hermite(s)
        if tol_mm >= INVERSE_TOL_MM and inv.checked:
            return u
        lo, hi = inv.u_nodes[idx], inv.u_nodes[idx + 1]
        s_lo = inv.s_nodes[idx]
        a, b, u_node = lo.copy(), hi.copy(), lo
        for _ in range(_NEWTON_SWEEPS):
            err = s_lo + _gauss_integrals(self.speed, u_node, u) - s
            if not np.any(np.abs(err) > tol_mm):
                break
            a = np.where(err < 0, u, a)
            b = np.where(err > 0, u, b)
            speed = self.speed(u)
            newton = u - err / np.where(speed > 0, speed, np.inf)
            inside = (newton > a) & (newton < b)
            u = np.where(np.abs(err) > tol_mm, np.where(inside, newton, 0.5 * (a + b)), u)
        return u


@dataclass(frozen=True, eq=False)
class _InverseTable:
    """Nodes (u, s) with du/ds and d2u/ds2 at each sub-interval's two ends, seen from inside it
    (they may jump at knots), fine enough that quintic Hermite u(s) is within INVERSE_TOL_MM of
    arc length (checked at every midpoint; checked is False if the passes ran out first)."""

    u_nodes: np.ndarray
    s_nodes: np.ndarray
    lo: tuple[np.ndarray, np.ndarray]  # (du/ds, d2u/ds2) at each sub-interval's left end
    hi: tuple[np.ndarray, np.ndarray]  # and at its right end
    checked: bool

    @classmethod
    def build(cls, speed: SpeedFn, derivs: DerivsFn, u_nodes: np.ndarray,
              s_nodes: np.ndarray) -> _InverseTable:
        """Refine the arc-length table where the midpoint check fails: each failing sub-interval
        split in k parts, k from the error's h^6 scaling. Each sub-interval is checked once, when
        it is made; the derivatives found for that check are kept for the table."""
        u, pieces = u_nodes, np.diff(s_nodes)
        lo = hi = (np.zeros(0), np.zeros(0))
        fresh = np.ones(pieces.size, bool)
        for attempt in range(_INVERSE_PASSES + 1):
            k = np.flatnonzero(fresh)
            s = s_nodes[0] + np.concatenate(([0.0], np.cumsum(pieces)))
            lo_k = _u_derivatives(derivs(u[k]))
            lo = _scatter(lo, fresh, k, lo_k)
            hi = _scatter(hi, fresh, k, _u_derivatives(derivs(np.nextafter(u[k + 1], -np.inf))))
            table = cls(u, s, lo, hi, False)
            if attempt == _INVERSE_PASSES:
                return table  # unchecked: u_of_s then corrects by Newton
            u_mid = 0.5 * (u[k] + u[k + 1])
            s_mid = s[k] + _gauss_integrals(speed, u[k], u_mid)
            err = np.abs(table.hermite(s_mid)[0] - u_mid) / np.where(lo_k[0] > 0, lo_k[0], 1.0)
            fail = err > 0.5 * INVERSE_TOL_MM
            if not fail.any():
                return cls(u, s, lo, hi, True)
            parts = np.clip(np.ceil(1.25 * (err[fail] / INVERSE_TOL_MM) ** (1 / 6)), 2, 64)
            u, pieces, fresh, lo, hi = _split(speed, u, pieces, lo, hi, k[fail],
                                              parts.astype(np.intp))
        raise AssertionError("unreachable")

    def hermite(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, sub-interval index) of arc lengths s by quintic Hermite in their sub-intervals."""
        idx = np.clip(np.searchsorted(self.s_nodes, s, side="right") - 1, 0,
                      self.u_nodes.size - 2)
        s0, h = self.s_nodes[idx], self.s_nodes[idx + 1] - self.s_nodes[idx]
        h = np.where(h > 0, h, 1.0)
        x = np.clip((s - s0) / h, 0.0, 1.0)
        u0, u1 = self.u_nodes[idx], self.u_nodes[idx + 1]
        d0, d1 = self.lo[0][idx] * h, self.hi[0][idx] * h
        c0, c1 = self.lo[1][idx] * h * h, self.hi[1][idx] * h * h
        x2 = x * x
        x3 = x2 * x
        m = 1 - x
        m2 = m * m
        m3 = m2 * m
        # Quintic Hermite basis in Bernstein-like form (values, slopes, curvatures at both ends).
        u = (m3 * (1 + 3 * x + 6 * x2) * u0 + x3 * (1 + 3 * m + 6 * m2) * u1
             + m3 * x * (1 + 3 * x) * d0 - x3 * m * (1 + 3 * m) * d1
             + 0.5 * m3 * x2 * c0 + 0.5 * x3 * m2 * c1)
        return np.clip(u, u0, u1), idx


def _u_derivatives(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(du/ds, d2u/ds2) = (1/|C'|, -(C'.C'')/|C'|^4) from d = [C, C', C''] (0 where |C'| = 0)."""
    g = np.einsum("ni,ni->n", d[1], d[1])
    dot = np.einsum("ni,ni->n", d[1], d[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.where(g > 0, 1.0 / np.sqrt(g), 0.0), np.where(g > 0, -dot / (g * g), 0.0))


def _scatter(old: tuple[np.ndarray, np.ndarray], fresh: np.ndarray, k: np.ndarray,
             new: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Per-interval pairs: the old values where not fresh, the new ones at the fresh k."""
    out = []
    for o, n in zip(old, new, strict=True):
        full = np.empty(fresh.size)
        full[~fresh] = o
        full[k] = n
        out.append(full)
    return out[0], out[1]


def _split(speed: SpeedFn, u: np.ndarray, pieces: np.ndarray, lo: tuple, hi: tuple,
           bad: np.ndarray, parts: np.ndarray) -> tuple:
    """Split sub-intervals bad into parts each: new nodes, arc lengths of every sub-interval
    (Gauss-Legendre on the new ones), fresh flags, and the kept intervals' derivatives."""
    inner = parts - 1
    i = np.repeat(bad, inner)
    j = np.arange(inner.sum()) - np.repeat(np.cumsum(inner) - inner, inner) + 1
    new_u = u[i] + (u[i + 1] - u[i]) * (j / np.repeat(parts, inner))
    u2 = np.insert(u, i + 1, new_u)  # i is sorted and j rises within each interval
    added = np.zeros(pieces.size, np.intp)
    added[bad] = inner
    first = np.arange(pieces.size) + np.concatenate(([0], np.cumsum(added)[:-1]))
    keep = added == 0
    fresh = np.ones(u2.size - 1, bool)
    fresh[first[keep]] = False
    pieces2 = np.empty(u2.size - 1)
    pieces2[first[keep]] = pieces[keep]
    f = np.flatnonzero(fresh)
    pieces2[f] = _gauss_integrals(speed, u2[f], u2[f + 1])
    return u2, pieces2, fresh, (lo[0][keep], lo[1][keep]), (hi[0][keep], hi[1][keep])


def _hermite_start(s: np.ndarray, s_lo: np.ndarray, s_hi: np.ndarray, u_lo: np.ndarray,
                   u_hi: np.ndarray, v_lo: np.ndarray, v_hi: np.ndarray) -> np.ndarray:
    """u(s) by the cubic Hermite interpolant on [s_lo, s_hi]; linear where a speed is zero."""
    h = s_hi - s_lo
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(h > 0, (s - s_lo) / np.where(h > 0, h, 1.0), 0.0)
        m0 = np.where(v_lo > 0, h / np.where(v_lo > 0, v_lo, 1.0), u_hi - u_lo)
        m1 = np.where(v_hi > 0, h / np.where(v_hi > 0, v_hi, 1.0), u_hi - u_lo)
    x2, x3 = x * x, x * x * x
    u = ((2 * x3 - 3 * x2 + 1) * u_lo + (x3 - 2 * x2 + x) * m0 + (-2 * x3 + 3 * x2) * u_hi
         + (x3 - x2) * m1)
    return np.clip(u, u_lo, u_hi)
