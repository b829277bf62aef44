"""A planar tool path as a chain of pieces (NURBS parts, PH corners, lines, arcs) in arc length."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from controller.geometry.curves import ConstantSpeedCurve, Curve
from controller.numeric import cached_property, clamp, sorted_unique


class PieceKind(StrEnum):
    NURBS = "nurbs"  # a non-corner NURBS part: Taylor interpolator
    PH = "ph"  # a PH quintic corner: exact arc length, Newton interpolator
    LINE = "line"
    ARC = "arc"


@dataclass(frozen=True, eq=False, repr=False)
class Piece:
    """The part [u0, u1] of a curve; s0_mm is where it starts along the whole path."""

    kind: PieceKind
    curve: Curve
    u0: float
    u1: float
    s0_mm: float
    length_mm: float
    feed_mm_s: float  # programmed feed (capped by the machine's limit)
    line: int  # NC source line
    corner: int = -1  # index of the corner zone this PH piece belongs to, -1 otherwise

    @property
    def curve_s0_mm(self) -> float:
        """Arc length of the curve before u0 (the piece's offset inside its curve)."""
        return float(self.curve.s_of_u(np.array([self.u0]))[0])

    def u_at(self, s_path_mm: np.ndarray) -> np.ndarray:
        """Exact curve parameters at path arc lengths inside this piece."""
        local = clamp(s_path_mm - self.s0_mm, 0.0, self.length_mm)
        u = self.curve.u_of_s(local + self.curve_s0_mm)
        return clamp(u, min(self.u0, self.u1), max(self.u0, self.u1))


_KIND_CODE = {PieceKind.NURBS: 0, PieceKind.PH: 1, PieceKind.LINE: 2, PieceKind.ARC: 3}


@dataclass(frozen=True, eq=False, repr=False)
class PieceColumns:
    """Per piece of a path, read-only arrays: where it starts, its length, its parameter range,
    programmed feed, source line, corner and kind (a path of G1 lines has thousands of pieces;
    a list comprehension per field and consumer cost a tenth of its planning)."""

    s0_mm: np.ndarray
    length_mm: np.ndarray
    u0: np.ndarray
    u1: np.ndarray
    feed_mm_s: np.ndarray
    line: np.ndarray  # int32
    corner: np.ndarray  # intp
    kind: np.ndarray  # int8: _KIND_CODE

    @classmethod
    def of(cls, pieces: tuple[Piece, ...]) -> PieceColumns:
        rows = np.array([(p.s0_mm, p.length_mm, p.u0, p.u1, p.feed_mm_s, p.line, p.corner)
                         for p in pieces], float).reshape(-1, 7)
        kind = np.array([_KIND_CODE[p.kind] for p in pieces], np.int8)
        cols = [np.ascontiguousarray(c) for c in rows.T]
        out = cls(*cols[:5], cols[5].astype(np.int32), cols[6].astype(np.intp), kind)
        for a in (*cols[:5], out.line, out.corner, kind):
            a.flags.writeable = False
        return out

    def of_kind(self, kind: PieceKind) -> np.ndarray:
        """Whether each piece is of that kind."""
        return self.kind == _KIND_CODE[kind]


@dataclass(frozen=True, eq=False, repr=False)
class Path:
    """Pieces joined end to end; stops_at holds path positions where the feed must be zero."""

    pieces: tuple[Piece, ...]
    stops_at_mm: tuple[float, ...] = ()

    @property
    def length_mm(self) -> float:
        last = self.pieces[-1]
        return last.s0_mm + last.length_mm

    @cached_property
    def columns(self) -> PieceColumns:
        """The pieces' fields as arrays, made once for every consumer of the path."""
        return PieceColumns.of(self.pieces)

    @property
    def breaks_mm(self) -> np.ndarray:
        """Where each piece starts."""
        return self.columns.s0_mm

    def piece_index(self, s_mm: np.ndarray) -> np.ndarray:
        """Which piece each arc length falls in (the last piece owns the end point)."""
        return clamp(np.searchsorted(self.breaks_mm, s_mm, side="right") - 1, 0,
                       len(self.pieces) - 1)

    def _per_piece(self, s_mm: np.ndarray, fn) -> np.ndarray:  # noqa: ANN001
        s = np.asarray(s_mm, float)
        idx = self.piece_index(s)
        out: np.ndarray | None = None
        for i in sorted_unique(idx):
            mask = idx == i
            val = fn(self.pieces[i], s[mask])
            if out is None:
                out = np.zeros(s.shape + val.shape[1:], dtype=val.dtype)
            out[mask] = val
        assert out is not None
        return out

    def feed_cap(self, s_mm: np.ndarray) -> np.ndarray:
        """Programmed feed of the piece at each arc length."""
        return self._per_piece(s_mm, lambda p, s: np.full(s.shape, p.feed_mm_s))

    def line_at(self, s_mm: np.ndarray) -> np.ndarray:
        return self._per_piece(s_mm, lambda p, s: np.full(s.shape, p.line, dtype=np.int32))

    @property
    def end_xy(self) -> np.ndarray:
        p = self.pieces[-1]
        return p.curve.evaluate(np.array([p.u1]), 0)[0, 0]


def new_piece(kind: PieceKind, curve: Curve, u0: float, u1: float, s0_mm: float,
              length_mm: float, feed_mm_s: float, line: int, corner: int = -1) -> Piece:
    """Piece(...) with its fields set as they are, without the frozen dataclass's setattr per
    field (half the cost; a G1 program makes four pieces per joint)."""
    p = object.__new__(Piece)
    p.__dict__.update(kind=kind, curve=curve, u0=u0, u1=u1, s0_mm=s0_mm, length_mm=length_mm,
                      feed_mm_s=feed_mm_s, line=line, corner=corner)
    return p


def make_piece(kind: PieceKind, curve: Curve, u0: float, u1: float, s0_mm: float,
               feed_mm_s: float, line: int, corner: int = -1) -> Piece:
    """A piece with its length measured on the curve."""
    if isinstance(curve, ConstantSpeedCurve):  # s = u * length: s_of_u's numbers, in Python
        length = curve.length_mm
        return new_piece(kind, curve, u0, u1, s0_mm, u1 * length - u0 * length, feed_mm_s,
                         line, corner)
    s = curve.s_of_u(np.array([u0, u1]))
    return Piece(kind, curve, u0, u1, s0_mm, float(s[1] - s[0]), feed_mm_s, line, corner)


def chain(pieces: list[Piece], own: list[bool] | None = None) -> tuple[Piece, ...]:
    """Re-number the path offsets so the pieces follow each other. own[i]: piece i was made
    for this chain alone (no cache or earlier path holds it), so it is moved in place instead
    of copied (a G1 window has four pieces per joint)."""
    out: list[Piece] = []
    s0 = 0.0
    for i, p in enumerate(pieces):
        if own is not None and own[i]:
            p.__dict__["s0_mm"] = s0
            out.append(p)
        else:
            out.append(_moved(p, s0))
        s0 += p.length_mm
    return tuple(out)


def _moved(p: Piece, s0_mm: float) -> Piece:
    """p starting at s0_mm: its fields copied as they are (a third of the cost of the frozen
    dataclass's constructor, and chain moves every piece of a window)."""
    moved = object.__new__(Piece)
    fields = moved.__dict__
    fields.update(p.__dict__)
    fields["s0_mm"] = s0_mm
    return moved


# A first derivative below this share of a piece's mean |dC/du| has no direction: the end of a
# NURBS split at a cusp (interpreter/nurbs_blocks.py), where the curve stops and turns back.
DEGENERATE_SPEED = 1e-9


def _end_derivative(piece: Piece, at_end: bool) -> tuple[np.ndarray, bool]:
    """dC/du at the piece's end (at_end) or start, and whether it is too small to point."""
    u = piece.u1 if at_end else piece.u0
    d = piece.curve.evaluate(np.array([u]), 1)[1, 0]
    mean_speed = piece.length_mm / max(abs(piece.u1 - piece.u0), 1e-300)
    return d, float(np.hypot(d[0], d[1])) <= DEGENERATE_SPEED * mean_speed


def degenerate_end(piece: Piece, at_end: bool) -> bool:
    return _end_derivative(piece, at_end)[1]


def end_tangent(piece: Piece, at_end: bool) -> np.ndarray:
    """The unit direction of travel at the piece's end (at_end) or start. Where dC/du vanishes,
    it is the second derivative's, reversed on arrival (dC/du ~ C''(u) (u - u_end) < 0 there)."""
    d, degenerate = _end_derivative(piece, at_end)
    if degenerate:
        u = piece.u1 if at_end else piece.u0
        d2 = piece.curve.evaluate(np.array([u]), 2)[2, 0]
        if float(np.hypot(d2[0], d2[1])) > 0.0:
            d = -d2 if at_end else d2
    return d / max(float(np.hypot(d[0], d[1])), 1e-300)
