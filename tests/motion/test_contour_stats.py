"""The measured contour error (motion/checks.ContourStats), taken BATCH_ROWS encoder rows at a
time: the same figures as one cycle's rows at a time, and those of every segment measured."""

from __future__ import annotations

import numpy as np
import pytest

from controller.motion import checks
from controller.motion.checks import ContourStats, RefHistory
from controller.numeric import segment_distance


def _fed(batch_rows: int, monkeypatch: pytest.MonkeyPatch) -> dict[str, float]:
    """A circle of 3000 frames sent 2 a cycle, 42 ahead of execution (NEAR_FRAMES ahead, as
    the card's FIFO keeps them); the tool 2 frames behind with a wobble, its encoder rows
    given 2 a cycle, the last ones after the last frame was sent."""
    monkeypatch.setattr(checks, "BATCH_ROWS", batch_rows)
    pulse_mm = np.array([0.001, 0.001])
    t = np.linspace(0.0, 2 * np.pi, 3000)
    path = np.column_stack((20 * np.cos(t), 20 * np.sin(t)))
    hist = RefHistory(1500, 2, 0.001)
    stats = ContourStats(pulse_mm)
    sent = executed = 0
    while executed < len(path):
        take = path[sent:sent + 2]
        hist.append(take, np.full(len(take), 10.0), np.ones(len(take), np.int64),
                    path[max(sent - 1, 0)])
        sent += len(take)
        if sent > checks.NEAR_FRAMES or sent == len(path):
            seq = np.arange(executed, min(executed + 2, len(path)))
            lag = path[np.maximum(seq - 2, 0)] + 0.01 * np.sin(seq)[:, None]
            stats.update_at(seq, np.round(lag / pulse_mm), hist)
            executed += len(seq)
    return stats.summary_um()


def test_batched_rows_give_the_figures_of_rows_one_cycle_at_a_time(
        monkeypatch: pytest.MonkeyPatch) -> None:
    one, batched = _fed(1, monkeypatch), _fed(128, monkeypatch)
    assert batched["max"] == one["max"] and one["max"] > 5.0
    assert batched["rms"] == pytest.approx(one["rms"], rel=1e-12)
    assert batched["mean"] == pytest.approx(one["mean"], rel=1e-12)


def test_measured_distance_is_the_least_over_every_segment_of_the_window() -> None:
    """Against every segment measured, over a ring that wrapped, a stop (frames repeated) and
    windows clipped at both ends of the frames kept."""
    rng = np.random.default_rng(7)
    pulse_mm = np.array([0.001, 0.001, 0.001])
    steps = rng.normal(scale=0.02, size=(700, 3))
    steps[300:340] = 0.0  # at rest: the same frame forty times
    path = np.cumsum(steps, axis=0)
    hist = RefHistory(256, 3, 0.001)
    for lo in range(0, len(path), 50):
        hist.append(path[lo:lo + 50], np.ones(50), np.ones(50, np.int64), path[max(lo - 1, 0)])
    kept = np.arange(len(path) - hist.capacity, len(path))
    seq = np.concatenate([kept[:30], kept[100:230], kept[-20:]])
    counts = np.round((path[seq] + rng.normal(scale=0.01, size=(len(seq), 3))) / pulse_mm)
    stats = ContourStats(pulse_mm)
    stats.update_at(seq, counts, hist)
    got = stats.summary_um()
    win = np.clip(seq[:, None] + np.arange(-checks.NEAR_FRAMES, checks.NEAR_FRAMES + 1),
                  kept[0], kept[-1])
    poly = path[win]
    want = segment_distance((counts * pulse_mm)[:, None], poly[:, :-1], poly[:, 1:]).min(axis=1)
    assert got["max"] == pytest.approx(want.max() * 1e3, rel=1e-12, abs=1e-9)
    assert got["mean"] == pytest.approx(want.mean() * 1e3, rel=1e-12, abs=1e-9)
    assert got["rms"] == pytest.approx(np.sqrt(np.mean(want**2)) * 1e3, rel=1e-12, abs=1e-9)
