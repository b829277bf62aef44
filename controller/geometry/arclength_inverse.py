"""The inverse u(s) of an arc-length table, built lazily where asked: checked quintic Hermite."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from controller.numeric import clamp, sorted_unique

SpeedFn = Callable[[np.ndarray], np.ndarray]  # |C'(u)| for an array of u
DerivsFn = Callable[[np.ndarray], np.ndarray]  # [C, C', C''] as x, y rows (3, 2, N)
IntegralFn = Callable[[SpeedFn, np.ndarray, np.ndarray], np.ndarray]  # speed over [a_i, b_i]

# Quintic Hermite u(s) is checked to this at every sub-interval's midpoint. 1e-11 mm of position
# along the path is 1e-5 mm/s of feed at T = 1 ms: far below what any check sees, so the
# generator's interpolation needs no Newton step at all.
INVERSE_TOL_MM = 1e-11
_PASSES = 6
MAX_ROWS = 50_000  # sub-intervals one refinement may make (3.6 MB); the rest uses Newton


@dataclass(eq=False, repr=False)
class InverseTable:
    """Sub-intervals [u0, u1] with their arc lengths [s0, s1] and (du/ds, d2u/ds2) at both ends
    (seen from inside: they may jump at knots). Built per interval of the arc-length table the
    first time an arc length inside it is asked for, so the parts of a curve that are never
    interpolated (its corner zones, replaced by PH quintics) cost nothing."""

    speed: SpeedFn
    derivs: DerivsFn
    integrate: IntegralFn
    base_u: np.ndarray  # the arc-length table's nodes
    base_s: np.ndarray
    built: np.ndarray = field(init=False)
    rows: np.ndarray = field(init=False)  # (n, 9): u0 u1 s0 s1 d0 c0 d1 c1 checked, by s0
    _s0: np.ndarray = field(init=False)  # rows[:, 2], contiguous

    def __post_init__(self) -> None:
        self.built = np.zeros(self.base_u.size - 1, bool)
        self.rows = np.empty((0, 9))
        self._s0 = np.empty(0)

    def ensure(self, s: np.ndarray) -> None:
        """Build the sub-intervals covering every arc length in s (in place)."""
        base = clamp(np.searchsorted(self.base_s, s, side="right") - 1, 0, self.built.size - 1)
        need = sorted_unique(base[~self.built[base]])
        if need.size == 0:
            return
        new = _refine(self, self.base_u[need], self.base_u[need + 1], self.base_s[need],
                      self.base_s[need + 1] - self.base_s[need])
        rows = np.concatenate((self.rows, new))
        self.rows = rows[np.argsort(rows[:, 2], kind="stable")]
        self._s0 = np.ascontiguousarray(self.rows[:, 2])  # searched on every hermite call
        self.built[need] = True

    def interval(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u0, u1, s0) of sub-intervals idx."""
        return self.rows[idx, 0], self.rows[idx, 1], self.rows[idx, 2]

    def checked(self, idx: np.ndarray) -> bool:
        """Whether every sub-interval idx passed its midpoint check."""
        return bool(np.all(self.rows[idx, 8] > 0))

    def hermite(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, sub-interval index) of arc lengths s (ensured) by quintic Hermite."""
        r = self.rows
        idx = clamp(np.searchsorted(self._s0, s, side="right") - 1, 0, len(r) - 1)
        u0, u1, s0, s1, d0, c0, d1, c1 = r.take(idx, axis=0)[:, :8].T  # one gather of the rows
        h = np.where(s1 > s0, s1 - s0, 1.0)
        return clamp(_quintic(clamp((s - s0) / h, 0.0, 1.0), h, u0, u1, d0, c0, d1, c1),
                       u0, u1), idx


def _quintic(x: np.ndarray, h: np.ndarray, u0: np.ndarray, u1: np.ndarray, d0: np.ndarray,
             c0: np.ndarray, d1: np.ndarray, c1: np.ndarray) -> np.ndarray:
    """Quintic Hermite on [0, 1] (values, slopes h d, curvatures h^2 c at both ends):
        m3 (1 + 3x + 6x2) u0 + x3 (1 + 3m + 6m2) u1 + h (m3 x (1 + 3x) d0 - x3 m (1 + 3m) d1)
        + 0.5 h h (m3 x2 c0 + x3 m2 c1),  m = 1 - x,
    in place, each product and sum in the order that expression is evaluated (1 + 3x and
    1 + 3m made once for both of their uses): the same numbers with fewer temporaries, for
    the hundreds of thousands of samples a long program interpolates."""
    x2 = x * x
    x3 = x2 * x
    m = 1 - x
    m2 = m * m
    m3 = m2 * m
    p = 3 * x
    p += 1
    q = 3 * m
    q += 1
    out = 6 * x2
    out += p
    out *= m3
    out *= u0
    t = 6 * m2
    t += q
    t *= x3
    t *= u1
    out += t
    t = m3 * x
    t *= p
    t *= d0
    p = x3 * m  # p (1 + 3x) is done with: the second product of h's term
    p *= q
    p *= d1
    t -= p
    t *= h
    out += t
    t = m3 * x2
    t *= c0
    p = x3 * m2
    p *= c1
    t += p
    q = 0.5 * h
    q *= h
    t *= q
    out += t
    return out


def _u_derivatives(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(du/ds, d2u/ds2) = (1/|C'|, -(C'.C'')/|C'|^4) from rows d = [C, C', C''] (3, 2, N)
    (0 where |C'| = 0); each dot product the sum of its two products, as an einsum was."""
    (x1, y1), (x2, y2) = d[1], d[2]
    g = x1 * x1 + y1 * y1
    dot = x1 * x2 + y1 * y2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(g > 0, 1.0 / np.sqrt(g), 0.0), np.where(g > 0, -dot / (g * g), 0.0)


def _refine(t: InverseTable, u0: np.ndarray, u1: np.ndarray, s0: np.ndarray,
            length: np.ndarray) -> np.ndarray:
    """Rows for the intervals [u0, u1]: each checked at its midpoint and, failing, split in k
    parts (k from the error's h^6 scaling) that are checked in turn."""
    done: list[np.ndarray] = []
    rows = 0
    for attempt in range(_PASSES + 1):
        # Both ends in one curve evaluation (the end seen from inside: just below u1).
        dd, cc = _u_derivatives(t.derivs(np.concatenate((u0, np.nextafter(u1, -np.inf)))))
        d0, c0, d1, c1 = dd[:u0.size], cc[:u0.size], dd[u0.size:], cc[u0.size:]
        if attempt == _PASSES:  # out of passes: kept, unchecked (u_of_s then uses Newton)
            done.append(_rows(slice(None), u0, u1, s0, length, d0, c0, d1, c1, checked=False))
            break
        u_mid = 0.5 * (u0 + u1)
        s_mid = s0 + t.integrate(t.speed, u0, u_mid)
        h = np.where(length > 0, length, 1.0)
        x = clamp((s_mid - s0) / h, 0.0, 1.0)
        err = np.abs(_quintic(x, h, u0, u1, d0, c0, d1, c1) - u_mid) / np.where(d0 > 0, d0, 1.0)
        fail = err > 0.5 * INVERSE_TOL_MM
        ok = ~fail
        done.append(_rows(ok, u0, u1, s0, length, d0, c0, d1, c1, checked=True))
        rows += int(ok.sum())
        if not fail.any():
            break
        parts = clamp(np.ceil(1.25 * (err[fail] / INVERSE_TOL_MM) ** (1 / 6)), 2, 64)
        if rows + int(parts.sum()) > MAX_ROWS:
            # Out of rows: kept, unchecked, like out of passes. Splitting by up to 64 a pass,
            # a knot span 1e4 times narrower than its neighbours grew 489,533 rows (1 GB).
            done.append(_rows(fail, u0, u1, s0, length, d0, c0, d1, c1, checked=False))
            break
        u0, u1, s0, length = _split(t, u0[fail], u1[fail], s0[fail], parts.astype(np.intp))
    return np.concatenate(done)


def _rows(pick: np.ndarray | slice, u0: np.ndarray, u1: np.ndarray, s0: np.ndarray,
          length: np.ndarray, d0: np.ndarray, c0: np.ndarray, d1: np.ndarray, c1: np.ndarray,
          checked: bool) -> np.ndarray:
    """Table rows (u0 u1 s0 s1 d0 c0 d1 c1 checked) of the intervals picked."""
    u0 = u0[pick]
    return np.column_stack((u0, u1[pick], s0[pick], s0[pick] + length[pick], d0[pick],
                            c0[pick], d1[pick], c1[pick], np.full(u0.size, float(checked))))


def _split(t: InverseTable, u0: np.ndarray, u1: np.ndarray, s0: np.ndarray,
           parts: np.ndarray) -> tuple[np.ndarray, ...]:
    """Each interval in parts equal pieces in u: their ends, starts in s and lengths."""
    parent = np.repeat(np.arange(u0.size), parts)
    j = np.arange(parent.size) - np.repeat(np.cumsum(parts) - parts, parts)
    width = (u1 - u0)[parent]
    a = u0[parent] + width * (j / parts[parent])
    b = np.where(j + 1 == parts[parent], u1[parent], u0[parent] + width * ((j + 1) / parts[parent]))
    length = t.integrate(t.speed, a, b)
    before = np.cumsum(length) - length  # running sum, restarted per parent below
    start = before - np.repeat(before[np.cumsum(parts) - parts], parts)
    return a, b, s0[parent] + start, length
