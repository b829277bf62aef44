"""The tool's true distance from the path (beyond eq. 28): the servo model's actual position
against the polyline of reference points near it, every sample, the settling after the run
included. Around a stop it is the overshoot eq. 28 cannot see."""

from __future__ import annotations

import numpy as np

from controller.servo.prediction import ServoPrediction
from controller.servo.window_search import (
    consecutive,
    pruned_window_distance_mm,
    squared_gap,
)

# Reference segments searched each side of a sample's own: the modelled tool is never further
# along the path than this from its reference (at 1 ms, 40 samples hold 50 um even at 1.25 mm/s).
NEAR_SAMPLES = 40
WINDOW_BLOCK = 512  # samples measured at once: their temporaries stay in the cache


def held_reference(xy_mm: np.ndarray, pred: ServoPrediction) -> np.ndarray:
    """The reference over the run and the settling after it (the end point held)."""
    settle = len(pred.ex_mm) - len(xy_mm)
    return np.vstack([xy_mm, np.repeat(xy_mm[-1:], settle, axis=0)])


def true_error_mm(xy_mm: np.ndarray, pred: ServoPrediction, exact_above_mm: float = 0.0,
                  near: int = NEAR_SAMPLES, history_xy: np.ndarray | None = None) -> np.ndarray:
    """Per sample (run and settling): the distance of the modelled tool from the path (see
    distance_from_reference_mm for exact_above_mm). history_xy, for a run continuing a
    look-ahead window, is the reference just before its first sample: the polyline starts
    there, so the tool still lagging behind the cut is measured to the path, not to its end."""
    ref = held_reference(xy_mm, pred)
    act = ref - np.column_stack([pred.ex_mm, pred.ey_mm])
    if history_xy is None or not len(history_xy):
        return distance_from_reference_mm(ref, act, exact_above_mm, near)
    k = len(history_xy)  # their own distances (zero: act there is the reference) are dropped
    return distance_from_reference_mm(np.vstack([history_xy, ref]), np.vstack([history_xy, act]),
                                      exact_above_mm, near)[k:]


def distance_from_reference_mm(ref: np.ndarray, act: np.ndarray, exact_above_mm: float = 0.0,
                               near: int = NEAR_SAMPLES) -> np.ndarray:
    """Each actual point's distance from the reference polyline within `near` segments of its
    own sample. The polyline is the path to within its chord error, a fraction of a um at the
    feeds the curvature allows. The distance to the two segments at its own sample bounds it
    from above: where that bound is at most exact_above_mm, the bound is returned (the loop
    only needs to know such samples are within the limit, and skips most of the work)."""
    n = len(ref)
    if n < 2:
        return np.hypot(*(act - ref).T)
    pad, bound = _padded_bound(ref, act, near)
    k = np.flatnonzero(bound > exact_above_mm)
    if k.size == 0:
        return bound
    out = bound.copy()
    out[k] = padded_window_distance_mm(pad, act[k], k, near, bound[k])
    return out


def _padded_bound(ref: np.ndarray, act: np.ndarray,
                  near: int) -> tuple[list[np.ndarray], np.ndarray]:
    """The padded columns of ref's segments (window_distance_mm's), and each actual point's
    distance from the segments before and at its own sample (clipped to the polyline):
    padded index near + j holds segment clip(j, 0, n - 2), so those are two slices."""
    n = len(ref)
    pad = padded_columns(segment_columns(ref), near)
    before, at = slice(near - 1, near - 1 + n), slice(near, near + n)
    return pad, own_bound_mm(pad, act, before, at)


def segment_columns(ref: np.ndarray) -> tuple[np.ndarray, ...]:
    """(a_x, a_y, ab_x, ab_y, |ab|^2 or 1) of each segment of the polyline ref: the terms
    numeric.segment_distance forms per point, here once per segment."""
    a = ref[:-1]
    ab = ref[1:] - a
    len2 = ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1]
    return (a[:, 0], a[:, 1], ab[:, 0], ab[:, 1], np.where(len2 > 0.0, len2, 1.0))


def own_bound_mm(columns: tuple[np.ndarray, ...], points: np.ndarray, before: np.ndarray | slice,
                 at: np.ndarray | slice) -> np.ndarray:
    """Per point, the lesser of its distances from segments before and at of columns:
    numeric.segment_distance's numbers (the same operations on the same terms; the square root
    of the lesser square is the lesser root), without its (n, 2) temporaries and sums."""
    ax, ay, abx, aby, den = columns
    px, py = points[..., 0], points[..., 1]
    gaps = [squared_gap(px - ax[j], py - ay[j], abx[j], aby[j], den[j]) for j in (before, at)]
    return np.sqrt(np.minimum(gaps[0], gaps[1]))


def padded_columns(columns: tuple[np.ndarray, ...], near: int) -> list[np.ndarray]:
    """The columns with near copies of the first segment before and of the last after."""
    return [np.concatenate((np.full(near, c[0]), c, np.full(near, c[-1]))) for c in columns]


def window_distance_mm(ref: np.ndarray, points: np.ndarray, k: np.ndarray,
                       near: int = NEAR_SAMPLES,
                       upper_mm: np.ndarray | None = None) -> np.ndarray:
    """For the samples k (sorted), the distance of points (one per k) from the segments j of
    ref with j in [k - near, k + near) (clipped to the polyline), exactly as
    numeric.segment_distance gives it for each and the least taken. Segment terms are formed
    once per segment and the windows are views of them (padded at both ends as the clipping
    would repeat the end segments); the square root is taken of the least squared distance
    (sqrt is monotonic: the same number). 12 times faster than segment_distance on gathered
    windows of 80 segments, so `cncctl simulate` can measure every sample exactly.

    upper_mm (per point, at least its distance: that from its own segments) lets the search
    skip the segments that cannot come that close (window_search.py): the same numbers."""
    pad = padded_columns(segment_columns(ref), near)
    return padded_window_distance_mm(pad, points, k, near, upper_mm)


def padded_window_distance_mm(pad: list[np.ndarray], points: np.ndarray, k: np.ndarray,
                              near: int, upper_mm: np.ndarray | None = None) -> np.ndarray:
    """window_distance_mm on the padded columns of the polyline's segments."""
    if upper_mm is not None:
        found = pruned_window_distance_mm(pad, points, k, near, upper_mm)
        lost = np.flatnonzero(~np.isfinite(found))  # a bound that was not one (NaN): search all
        if lost.size:
            found[lost] = padded_window_distance_mm(pad, points[lost], k[lost], near)
        return found
    # Padded index k + m (m < 2 near) holds segment clip(k - near + m, 0, n - 2).
    views = [np.lib.stride_tricks.sliding_window_view(c, 2 * near) for c in pad]
    out = np.empty(k.size)
    contiguous = consecutive(k)
    for lo in range(0, k.size, WINDOW_BLOCK):
        kb = k[lo:lo + WINDOW_BLOCK]
        sel = slice(int(kb[0]), int(kb[-1]) + 1) if contiguous else kb
        ax, ay, abx, aby, den = (v[sel] for v in views)
        p = points[lo:lo + WINDOW_BLOCK]
        px, py = p[:, 0][:, None], p[:, 1][:, None]
        out[lo:lo + WINDOW_BLOCK] = np.sqrt(squared_gap(px - ax, py - ay, abx, aby, den)
                                            .min(axis=1))
    return out


def worst_true_error_mm(xy_mm: np.ndarray, preds: tuple[ServoPrediction, ...],
                        exact_above_mm: float = 0.0, near: int = NEAR_SAMPLES,
                        history_xy: np.ndarray | None = None) -> np.ndarray:
    """Per sample, the largest true_error_mm over several plants' predictions of the same
    reference (a servo band, servo/band.py), all plants in one pass: their bounds together,
    then one exact search over every (sample, plant) whose bound is above exact_above_mm."""
    ref = held_reference(xy_mm, preds[0])
    acts = np.stack([ref - np.column_stack([p.ex_mm, p.ey_mm]) for p in preds])
    k0 = 0 if history_xy is None else len(history_xy)
    if k0:
        ref = np.vstack([history_xy, ref])
        acts = np.concatenate([np.broadcast_to(history_xy, (len(preds), k0, 2)), acts], axis=1)
    n = len(ref)
    if n < 2:
        return np.hypot(*(acts - ref).transpose(2, 0, 1)).max(axis=0)[k0:]
    pad, bound = _padded_bound(ref, acts, near)  # (plant, sample)
    k, plant = np.nonzero((bound > exact_above_mm).T)  # sorted by sample: the search's order
    if k.size:
        bound[plant, k] = padded_window_distance_mm(pad, acts[plant, k], k, near,
                                                    bound[plant, k])
    return bound.max(axis=0)[k0:]
