"""Synthetic reference streams for runtime tests: quintic-feed lines and circles from rest."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from controller.refpoints import RefChunk


def quintic_distance_mm(length_mm: float, v_mm_s: float, accel_mm_s2: float,
                        period_s: float) -> np.ndarray:
    """Sampled s(t) of an accel/cruise/decel quintic feed plan (docs/algorithms.md, Feed planning),
    rest to rest."""
    vc = min(v_mm_s, math.sqrt(16.0 * accel_mm_s2 * length_mm / 15.0 / 2.0))
    ta = 15.0 * vc / (8.0 * accel_mm_s2)
    tc = max(0.0, (length_mm - ta * vc) / vc)
    total = 2 * ta + tc
    t = np.arange(0, math.ceil(total / period_s) + 1) * period_s
    t = np.minimum(t, total)

    def ramp(tt: np.ndarray) -> np.ndarray:  # distance of a 0 -> vc quintic over ta
        tau = np.clip(tt / ta, 0.0, 1.0)
        f = np.array([0, 0, 0, 0, 1, 2, 3]) * vc * ta / 6.0
        k = np.arange(7)
        basis = np.array([math.comb(6, i) for i in k]) * tau[:, None] ** k \
            * (1 - tau[:, None]) ** (6 - k)
        return basis @ f

    s = ramp(t) + vc * np.clip(t - ta, 0.0, tc) + np.where(
        t > ta + tc, vc * (t - ta - tc) - ramp(np.maximum(0.0, t - ta - tc)), 0.0)
    s = np.minimum(s, length_mm)
    s[-1] = length_mm
    return s


def _chunks(pos_mm: np.ndarray, feed_mm_s: np.ndarray, period_s: float, size: int,
            line: int) -> Iterator[RefChunk]:
    n = len(pos_mm)
    for i in range(0, n, size):
        sl = slice(i, min(n, i + size))
        yield RefChunk(t0_s=i * period_s, pos_mm=pos_mm[sl], feed_mm_s=feed_mm_s[sl],
                       line=np.full(sl.stop - sl.start, line, dtype=np.int32),
                       final=sl.stop == n)


def circle_chunks(radius_mm: float = 10.0, v_mm_s: float = 58.333, accel_mm_s2: float = 2450.0,
                  period_s: float = 1e-3, size: int = 50, start_mm: tuple = (0.0, 0.0),
                  line: int = 3) -> Iterator[RefChunk]:
    """A full circle through start_mm (centre +R in x), quintic feed from rest to rest."""
    s = quintic_distance_mm(2 * math.pi * radius_mm, v_mm_s, accel_mm_s2, period_s)
    ang = math.pi + s / radius_mm
    pos = np.column_stack([start_mm[0] + radius_mm + radius_mm * np.cos(ang),
                           start_mm[1] + radius_mm * np.sin(ang)])
    pos[-1] = start_mm
    feed = np.gradient(s, period_s)
    return _chunks(pos, feed, period_s, size, line)


def line_chunks(end_mm: tuple, v_mm_s: float = 50.0, accel_mm_s2: float = 2450.0,
                period_s: float = 1e-3, size: int = 50, start_mm: tuple = (0.0, 0.0),
                line: int = 2) -> Iterator[RefChunk]:
    p0, p1 = np.asarray(start_mm, float), np.asarray(end_mm, float)
    length = float(np.linalg.norm(p1 - p0))
    s = quintic_distance_mm(length, v_mm_s, accel_mm_s2, period_s)
    pos = p0 + np.outer(s / length, p1 - p0)
    return _chunks(pos, np.gradient(s, period_s), period_s, size, line)


def fake_blocks(path: str, config: object) -> Iterator[int]:
    """Interpreter stand-in for runtime tests: three dummy blocks (the generator ignores them)."""
    yield from (1, 2, 3)


def fake_generate(blocks: object, config: object) -> Iterator[RefChunk]:
    """Generator stand-in: drains the NC FIFO, then streams a circle."""
    list(blocks)  # type: ignore[call-overload]
    yield from circle_chunks(radius_mm=5.0)


def slow_generate(blocks: object, config: object) -> Iterator[RefChunk]:
    """Generator stand-in that is slower than a virtual clock: 50 rows per 5 ms of wall time."""
    import time
    list(blocks)  # type: ignore[call-overload]
    for chunk in circle_chunks(radius_mm=5.0):
        time.sleep(0.005)
        yield chunk


def paced_generate(blocks: object, config: object) -> Iterator[RefChunk]:
    """Generator stand-in running at twice real time (50 rows per 25 ms), a 10 mm circle."""
    import time
    list(blocks)  # type: ignore[call-overload]
    for chunk in circle_chunks(radius_mm=10.0):
        time.sleep(0.025)
        yield chunk


def per_block_generate(blocks: object, config: object) -> Iterator[RefChunk]:
    """One 50-row chunk of a circle per NC block received (streams while blocks arrive)."""
    chunks = circle_chunks(radius_mm=10.0)
    for _ in blocks:  # type: ignore[attr-defined]
        yield next(chunks)
    yield from chunks


def many_blocks(path: str, config: object) -> Iterator[int]:
    yield from range(100)


def crashing_blocks(path: str, config: object) -> Iterator[int]:
    """The interpreter process dies hard after 8 blocks (a segfault stand-in)."""
    import os
    import time
    yield from range(8)
    time.sleep(0.2)
    os._exit(9)


def failing_generate(blocks: object, config: object) -> Iterator[RefChunk]:
    from controller.errors import PlanningError
    chunks = circle_chunks(radius_mm=10.0)
    for _ in range(8):
        yield next(chunks)
    raise PlanningError("contour error 41 um > 30 um after 20 dynamics rounds")


def erroring_blocks(path: str, config: object) -> Iterator[int]:
    """The interpreter raises an NcError mid-program (e.g. a file changed after the check)."""
    from controller.errors import NcError
    yield from range(8)
    raise NcError(path, 12, 5, "G5", "unknown G-code G5")


def hanging_generate(blocks: object, config: object) -> Iterator[RefChunk]:
    """Streams 400 rows of a 10 mm circle, then hangs (so a test can kill it mid-program)."""
    import time
    list(blocks)  # type: ignore[call-overload]
    chunks = circle_chunks(radius_mm=10.0)
    for _ in range(8):
        yield next(chunks)
    time.sleep(30.0)
    yield from chunks
