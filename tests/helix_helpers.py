"""Helpers for the helix tests: the modelled tool as the motion loop drives it, and a point's
distance from a 3-D polyline, computed apart from the generator's own check."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig
from controller.numeric import segment_distance
from controller.servo.model import discretise, tracking_error_mm
from controller.servo.precompensation import Precompensator
from controller.servo.prediction import SETTLE_S


def modelled_tool(ref: np.ndarray, start: np.ndarray, config: MachineConfig) -> np.ndarray:
    """The frames the motion loop sends (every axis pre-compensated when the config says so,
    the settling after the end included) through each axis's plant, from rest at start."""
    T = config.sample_period_s  # noqa: N806
    settle = int(round(SETTLE_S / T))
    if config.interpolator.servo_precompensation:
        sent = Precompensator([a.servo for a in config.axes], T, start).to_rest(ref)
    else:
        sent = ref
    tail = len(ref) + settle - len(sent)
    sent = np.vstack([sent, np.repeat(ref[-1:], max(tail, 0), axis=0)])
    v = np.diff(np.vstack([start, sent]), axis=0) / T
    return sent - np.column_stack([tracking_error_mm(discretise(a.servo, T), v[:, i])
                                   for i, a in enumerate(config.axes)])


def nearest_mm(points: np.ndarray, path: np.ndarray, reach_mm: float = 0.1) -> np.ndarray:
    """Each point's distance from the whole polyline (the segments whose box comes within
    reach_mm of a batch of points; a point further than that from all of them is inf)."""
    a, b = path[:-1], path[1:]
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    out = np.full(len(points), np.inf)
    for i0 in range(0, len(points), 128):
        q = points[i0:i0 + 128]
        near = np.all((seg_lo <= q.max(axis=0) + reach_mm) &
                      (seg_hi >= q.min(axis=0) - reach_mm), axis=1)
        if near.any():
            out[i0:i0 + 128] = segment_distance(q[:, None, :], a[None, near],
                                                b[None, near]).min(axis=1)
    return out
