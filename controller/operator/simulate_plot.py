"""Plots for `cncctl simulate --plot`: feedrate and contour error (paper Figures 3, 5, 6)."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig
from controller.operator.outputs import plot_format
from controller.runtime.simulate_stream import SampleBlock

MAX_POINTS = 20_000  # per series: a longer program is shown by buckets of samples


class PlotSeries:
    """Feed and eq. 28 contour error against time, gathered from the sample stream. Every
    sample while there are at most MAX_POINTS; beyond, buckets of 2, 4, 8 ... samples, each
    shown by its largest feed and its largest contour error in magnitude (so no peak is lost).
    """

    def __init__(self, config: MachineConfig) -> None:
        self.T = config.sample_period_s  # noqa: N815
        self.bucket = 1
        self.feed_t: list[np.ndarray] = []
        self.feed: list[np.ndarray] = []
        self.err_t: list[np.ndarray] = []
        self.err_um: list[np.ndarray] = []
        self.count = 0
        self.pending: list[tuple[np.ndarray, ...]] = []  # samples short of a whole bucket

    def add(self, b: SampleBlock) -> None:
        t = (b.i0 + 1 + np.arange(len(b))) * self.T
        feed = np.full(len(b), np.nan)  # none in the settling after the end
        feed[:b.n_ref] = b.feed_mm_s[:b.n_ref]
        err = np.where(b.contouring, b.contour_mm * 1000.0, np.nan)  # not on rapids
        self.pending.append((t, feed, err))
        self.count += len(b)
        self._reduce()

    def _reduce(self) -> None:
        t, feed, err = (np.concatenate(c) for c in zip(*self.pending, strict=True))
        whole = len(t) // self.bucket * self.bucket
        self.pending = [(t[whole:], feed[whole:], err[whole:])]
        if whole:
            self._keep(t[:whole], feed[:whole], err[:whole], self.bucket)
        while sum(len(x) for x in self.feed) > MAX_POINTS:
            self.bucket *= 2
            parts = [np.concatenate(x) for x in (self.feed_t, self.feed, self.err_t, self.err_um)]
            self.feed_t, self.feed, self.err_t, self.err_um = [], [], [], []
            even = len(parts[0]) // 2 * 2
            self._keep_pairs(parts, even)

    def _keep(self, t: np.ndarray, feed: np.ndarray, err: np.ndarray, k: int) -> None:
        """Buckets of k samples: the largest feed, and the contour error largest in magnitude."""
        if k == 1:
            self.feed_t.append(t)
            self.feed.append(feed)
            self.err_t.append(t)
            self.err_um.append(err)
            return
        tb, fb, eb = (x.reshape(-1, k) for x in (t, feed, err))
        self._store(tb, fb, tb, eb)

    def _keep_pairs(self, parts: list[np.ndarray], even: int) -> None:
        ft, f, et, e = parts
        self._store(ft[:even].reshape(-1, 2), f[:even].reshape(-1, 2), et[:even].reshape(-1, 2),
                    e[:even].reshape(-1, 2))
        if even < len(ft):  # an odd point left over stays as it is
            self.feed_t.append(ft[even:])
            self.feed.append(f[even:])
            self.err_t.append(et[even:])
            self.err_um.append(e[even:])

    def _store(self, ft: np.ndarray, f: np.ndarray, et: np.ndarray, e: np.ndarray) -> None:
        rows = np.arange(len(ft))
        fi = np.argmax(np.nan_to_num(f, nan=-np.inf), axis=1)
        ei = np.argmax(np.nan_to_num(np.abs(e), nan=-np.inf), axis=1)
        self.feed_t.append(ft[rows, fi])
        self.feed.append(f[rows, fi])
        self.err_t.append(et[rows, ei])
        self.err_um.append(e[rows, ei])

    def arrays(self) -> tuple[np.ndarray, ...]:
        """(feed t, feed, error t, error um), the samples short of a bucket included."""
        t, feed, err = self.pending[0] if self.pending else (np.zeros(0),) * 3
        cat = np.concatenate
        return (cat([*self.feed_t, t]), cat([*self.feed, feed]), cat([*self.err_t, t]),
                cat([*self.err_um, err]))


def plot_simulation(path: str, series: list[PlotSeries], reports: list[dict],
                    config: MachineConfig) -> None:
    """Feed and contour error against time, one column per algorithm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(series)
    fig, axes = plt.subplots(2, n, figsize=(5 * n, 6), squeeze=False, sharex="col")
    limit_um = config.interpolator.contour_error_limit_mm * 1000.0
    vmax = config.interpolator.max_feed_mm_s
    for col, (ser, rep) in enumerate(zip(series, reports, strict=True)):
        feed_t, feed, err_t, err_um = ser.arrays()
        ax_f, ax_e = axes[0, col], axes[1, col]
        ax_f.plot(feed_t, feed, lw=1)
        ax_f.axhline(vmax, color="grey", ls="--", lw=0.8)
        ax_f.set_title(f"{rep['algorithm']}: {rep['motion_time_s']:.3f} s")
        ax_f.set_ylabel("feed (mm/s)")
        ax_e.plot(err_t, err_um, lw=1, color="tab:red")
        for sign in (1, -1):
            ax_e.axhline(sign * limit_um, color="grey", ls="--", lw=0.8)
        ax_e.set_ylabel("contour error (um)")
        ax_e.set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format=plot_format(path))
    plt.close(fig)
