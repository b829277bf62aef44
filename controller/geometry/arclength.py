"""Arc length s(u) of a parametric curve by composite Gauss-Legendre, vectorised inverse u(s)."""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from controller.geometry.arclength_inverse import INVERSE_TOL_MM, DerivsFn, InverseTable, SpeedFn
from controller.geometry.gauss_legendre import W10, X10
from controller.numeric import clamp, sorted_unique

__all__ = ["INVERSE_TOL_MM", "ArcLengthTable"]

_GL_X, _GL_W = X10, W10  # 10-point Gauss-Legendre on each interval
_GL_ORDER = len(_GL_X)
MAX_KINK_SPLITS = 64  # intervals halved a round at most: kinks are few (bounded memory)
_NEWTON_SWEEPS = 60  # safeguarded: usually 1-2 sweeps, bisection at worst
_NEWTON_TOL_MM = 1e-11


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


def _refine_where_needed(speed: SpeedFn, nodes: np.ndarray, pieces: np.ndarray, tol_mm: float,
                         rounds: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Halve the sub-intervals whose integral its two halves change by more than their share of
    tol_mm (by width), until none does or more than MAX_KINK_SPLITS would: where the speed has
    a kink (a near-cusp) Gauss-Legendre converges only as the interval's square, and uniform
    doubling stopped 3e-7 mm short on one; intervals not split keep their integrals, and
    only the halves made in a round are tested in the next (the others passed already)."""
    width_mm = max(nodes[-1] - nodes[0], 1e-300)
    fresh = np.arange(len(pieces))  # intervals not tested yet: all, then the halves just made
    for _ in range(rounds):
        lo, hi = nodes[:-1], nodes[1:]
        mid = 0.5 * (lo + hi)
        a, m, b = lo[fresh], mid[fresh], hi[fresh]
        halves = _gauss_integrals(speed, np.concatenate((a, m)), np.concatenate((m, b)))
        left, right = halves[: len(a)], halves[len(a) :]
        bad = fresh[np.abs(left + right - pieces[fresh]) > tol_mm * (b - a) / width_mm]
        if not bad.size or bad.size > MAX_KINK_SPLITS:
            break  # converged, or not a few kinks (rounding everywhere): left as it is
        counts = np.ones(len(pieces), np.intp)
        counts[bad] = 2
        first = np.cumsum(counts) - counts  # each interval's first slot in the new arrays
        starts, pieces = np.repeat(lo, counts), np.repeat(pieces, counts)
        was = np.searchsorted(fresh, bad)  # bad's rows among the tested
        pieces[first[bad]], pieces[first[bad] + 1] = left[was], right[was]
        starts[first[bad] + 1] = mid[bad]
        nodes = np.append(starts, nodes[-1])
        fresh = np.sort(np.concatenate((first[bad], first[bad] + 1)))
    return nodes, pieces


@dataclass(frozen=True, eq=False, repr=False)
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
        brk = sorted_unique(np.asarray(breaks, dtype=float))
        m, previous = 2, None
        while True:
            u_nodes = _subdivide(brk, m)
            pieces = _gauss_integrals(speed, u_nodes[:-1], u_nodes[1:])
            total = float(pieces.sum())
            if previous is not None and abs(total - previous) <= rel_tol * max(total, 1e-300):
                break
            if m >= 1024:  # not converged: a near-cusp (|C'| ~ |u - u0|) somewhere
                u_nodes, pieces = _refine_where_needed(speed, u_nodes, pieces, rel_tol * total)
                break
            previous, m = total, m * 2
        return cls(speed, u_nodes, np.concatenate(([0.0], np.cumsum(pieces))), derivs)

    @property
    def total_length_mm(self) -> float:
        return float(self.s_nodes[-1])

    def _interval(self, u: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(self.u_nodes, u, side="right") - 1
        return clamp(idx, 0, self.u_nodes.size - 2)

    def s_of_u(self, u: ArrayLike) -> np.ndarray:
        """Arc length from the curve start to u (Gauss-Legendre on [u_node, u])."""
        uu = clamp(np.atleast_1d(np.asarray(u, dtype=float)), self.u_nodes[0], self.u_nodes[-1])
        idx = self._interval(uu)
        return self.s_nodes[idx] + _gauss_integrals(self.speed, self.u_nodes[idx], uu)

    def u_of_s_scalar(self, s_mm: float, lo: float, hi: float, tol_mm: float) -> float:
        """One parameter in [lo, hi] at arc length s_mm without the inverse table: linear
        between the nodes, then safeguarded Newton, each step one speed call for s(u) and
        s'(u) together. For the few points of a windowed blend's trials, where building the
        inverse over the span cost more than the trials themselves."""
        u = min(max(float(np.interp(s_mm, self.s_nodes, self.u_nodes)), lo), hi)
        a, b = lo, hi
        nodes, last = self.u_nodes, self.u_nodes.size - 2
        x = np.empty(_GL_ORDER + 1)  # the Gauss nodes on [u_node, u], then u itself
        for _ in range(_NEWTON_SWEEPS):
            idx = min(max(bisect.bisect_right(nodes, u) - 1, 0), last)  # _interval, no numpy
            u_node = self.u_nodes[idx]
            half = 0.5 * (u - u_node)
            np.add(0.5 * (u_node + u), half * _GL_X, out=x[:-1])
            x[-1] = u
            values = self.speed(x)
            err = float(self.s_nodes[idx] + half * (values[:-1] @ _GL_W)) - s_mm
            if abs(err) <= tol_mm:
                break
            a, b = (u, b) if err < 0 else (a, u)
            step = u - err / values[-1] if values[-1] > 0 else math.nan
            u = step if a < step < b else 0.5 * (a + b)
        return u

    @cached_property
    def _inverse(self) -> InverseTable:
        if self.derivs is None:
            raise ValueError("an inverse table needs the curve's derivatives")
        return InverseTable(self.speed, self.derivs, _gauss_integrals, self.u_nodes, self.s_nodes)

    def u_of_s(self, s_mm: ArrayLike, tol_mm: float = _NEWTON_TOL_MM) -> np.ndarray:
        """Inverse: quintic Hermite on the inverse table (built where first asked), then, when
        tol_mm is below INVERSE_TOL_MM or a sub-interval could not be checked, safeguarded
        Newton (bisection when a step leaves the bracket) to tol_mm."""
        s = clamp(np.atleast_1d(np.asarray(s_mm, dtype=float)), 0.0, self.total_length_mm)
        inv = self._inverse
        inv.ensure(s)
        u, idx = inv.hermite(s)
        if tol_mm >= INVERSE_TOL_MM and inv.checked(idx):
            return u
        lo, hi, s_lo = inv.interval(idx)
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
