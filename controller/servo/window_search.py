"""The exact least distance of points from windows of polyline segments, searched only where a
segment can come closer than a known upper bound (boxes of GROUP_SEGMENTS segments).

window_distance_mm forms every one of a sample's 2 near segments (80): the true contour error of
every sample of `cncctl simulate` was a tenth of simulating distinct airfoils. The tool is within
micrometres of its own segment, so a box of segments further along the path than that is passed
by its distance alone; the segments of the boxes that remain are formed with the very operations
of the full search, so the least of them (and its square root) is the same number, bit for bit.
"""

from __future__ import annotations

import numpy as np

GROUP_SEGMENTS = 8  # segments per bounding box
# A box is searched when it meets the square of half-side the bound and this margin of it around
# the point: the bound and the box come from other operations than the exact distance, so both
# may round the other way.
BOUND_SLACK_REL = 1e-6
BOUND_SLACK_MM = 1e-12
BLOCK_SAMPLES = 1024  # samples searched at once: their temporaries stay in the cache


def squared_gap(apx: np.ndarray, apy: np.ndarray, abx: np.ndarray, aby: np.ndarray,
                den: np.ndarray) -> np.ndarray:
    """Squared distance of P from segment AB, from P - A, AB and |AB|^2 (1 where zero): the
    one formula of both window searches, so that they give the same bits."""
    t = np.minimum(np.maximum((apx * abx + apy * aby) / den, 0.0), 1.0)
    gx, gy = apx - t * abx, apy - t * aby
    return gx * gx + gy * gy


def consecutive(k: np.ndarray) -> bool:
    """Whether k is k[0], k[0] + 1, ... (not only its ends: a band's samples repeat)."""
    return len(k) > 0 and bool((np.diff(k) == 1).all())


def pruned_window_distance_mm(columns: list[np.ndarray], points: np.ndarray, k: np.ndarray,
                              near: int, upper_mm: np.ndarray) -> np.ndarray:
    """Per point: the least distance over its window, padded segments k .. k + 2 near - 1 of
    columns (a_x, a_y, ab_x, ab_y, |ab|^2 or 1), given upper_mm >= that distance."""
    span = 2 * near
    groups = (span + GROUP_SEGMENTS - 2) // GROUP_SEGMENTS + 1  # the most a window touches
    boxes = _box_windows(_group_boxes(columns), groups)
    rows = _group_rows(columns)
    inside = _inside_table(span)
    out = np.empty(len(points))
    for lo in range(0, len(points), BLOCK_SAMPLES):
        sel = slice(lo, lo + BLOCK_SAMPLES)
        out[sel] = _block(rows, boxes, inside, points[sel], k[sel], span, upper_mm[sel])
    return out


def _group_rows(columns: list[np.ndarray]) -> list[np.ndarray]:
    """Each column as (group, GROUP_SEGMENTS) rows, the last group filled up with the last
    segment (never inside a window: read only to be masked)."""
    g = GROUP_SEGMENTS
    n_groups = -(-len(columns[0]) // g)
    out = []
    for c in columns:
        padded = np.empty(n_groups * g)
        padded[:len(c)] = c
        padded[len(c):] = c[-1]
        out.append(padded.reshape(n_groups, g))
    return out


def _inside_table(span: int) -> np.ndarray:
    """Row 9 a + b: which of a group's segments j lie in a window that starts a segments
    after the group's first and ends b after it (a, b clipped to 0..GROUP_SEGMENTS)."""
    g = GROUP_SEGMENTS
    j = np.arange(g)
    a, b = np.divmod(np.arange((g + 1) ** 2), g + 1)
    return (j >= a[:, None]) & (j < b[:, None])


def _group_boxes(columns: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """(x min, x max, y min, y max) of the segments of each group of GROUP_SEGMENTS. The least
    and the greatest of a group are taken one column at a time (a reduction along rows of 8 is
    numpy's slowest): the same numbers, as min and max do not round."""
    ax, ay, abx, aby, _ = columns
    n_groups = -(-len(ax) // GROUP_SEGMENTS)
    out = []
    for start, step in ((ax, abx), (ay, aby)):
        end = start + step
        for fill, pick in ((np.inf, np.minimum), (-np.inf, np.maximum)):
            padded = np.full(n_groups * GROUP_SEGMENTS, fill)
            padded[:len(start)] = pick(start, end)
            rows = padded.reshape(n_groups, GROUP_SEGMENTS)
            least = pick(rows[:, 0], rows[:, 1])
            for j in range(2, GROUP_SEGMENTS):
                pick(least, rows[:, j], out=least)
            out.append(least)
    return tuple(out)


def _box_windows(boxes: tuple[np.ndarray, ...], groups: int) -> tuple[np.ndarray, ...]:
    """Per box column, `groups` rows: row j holds the box j groups after each group (+inf
    low, -inf high past the last: never within reach), so that the boxes a window may touch
    are read without clipping: those of a window starting in group f are column f."""
    out = []
    for i, b in enumerate(boxes):
        padded = np.concatenate((b, np.full(groups, np.inf if i % 2 == 0 else -np.inf)))
        out.append(np.stack([padded[j:j + len(b)] for j in range(groups)]))
    return tuple(out)


def _block(rows: list[np.ndarray], boxes: tuple[np.ndarray, ...], inside_table: np.ndarray,
           points: np.ndarray, k: np.ndarray, span: int, upper_mm: np.ndarray) -> np.ndarray:
    """pruned_window_distance_mm of a block of points. The box tests are (group, point)
    arrays, so that every operation runs along contiguous rows; a box searched reads its
    segments as whole rows, each point repeated along them. Each box searched gives its
    least to a (group, point) table whose least per point is the answer."""
    ax, ay, abx, aby, den = rows
    run = consecutive(k)
    x_lo, x_hi, y_lo, y_hi = (_window_boxes(b, k, run) for b in boxes)  # (group, point)
    g = GROUP_SEGMENTS
    first = k // g
    px, py = points[:, 0], points[:, 1]
    reach = upper_mm * (1.0 + BOUND_SLACK_REL) + BOUND_SLACK_MM
    # A box is searched when it meets the square of half-side `reach` around the point (all
    # boxes within `reach` of it, and a few more at the square's corners).
    searched = x_lo <= px + reach
    searched &= x_hi >= px - reach
    searched &= y_lo <= py + reach
    searched &= y_hi >= py - reach
    # The last group touches the window only when the window does not start a group.
    searched[-1] &= (first + len(searched) - 1) * g < k + span
    box, point = np.nonzero(searched)
    group = first.take(point) + box
    start = k.take(point) - group * g  # the window's first segment from the group's first
    cut = np.clip(start, 0, g) * (g + 1) + np.clip(start + span, 0, g)
    inside = inside_table.take(cut, axis=0)
    gap2 = squared_gap(np.repeat(px.take(point), g).reshape(-1, g) - ax.take(group, axis=0),
                       np.repeat(py.take(point), g).reshape(-1, g) - ay.take(group, axis=0),
                       abx.take(group, axis=0), aby.take(group, axis=0),
                       den.take(group, axis=0))
    gap2[~inside] = np.inf
    least = gap2[:, 0].copy()
    for j in range(1, g):
        np.minimum(least, gap2[:, j], out=least)
    table = np.full(searched.shape, np.inf)
    table[box, point] = least
    return np.sqrt(table.min(axis=0))


def _window_boxes(rows: np.ndarray, k: np.ndarray, run: bool) -> np.ndarray:
    """(group, point): the boxes of the windows k, from _box_windows' rows. Consecutive
    windows (run) start GROUP_SEGMENTS at a time in the same group: their columns are
    repeated, not gathered one by one (the same numbers)."""
    g = GROUP_SEGMENTS
    if not run:
        return rows.take(k // g, axis=1)
    f0, lead = divmod(int(k[0]), g)
    f1 = int(k[-1]) // g
    return np.repeat(rows[:, f0:f1 + 1], g, axis=1)[:, lead:lead + len(k)]
