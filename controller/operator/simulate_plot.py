"""Plots for `cncctl simulate --plot`: feedrate and contour error (paper Figures 3, 5, 6)."""

from __future__ import annotations

import numpy as np

from controller.config import MachineConfig
from controller.runtime.simulation import Trajectory


def plot_simulation(path: str, trajectories: list[Trajectory], reports: list[dict],
                    config: MachineConfig) -> None:
    """Feed and contour error against time, one column per algorithm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(trajectories)
    fig, axes = plt.subplots(2, n, figsize=(5 * n, 6), squeeze=False, sharex="col")
    limit_um = config.interpolator.contour_error_limit_mm * 1000.0
    vmax = config.interpolator.max_feed_mm_s
    for col, (traj, rep) in enumerate(zip(trajectories, reports, strict=True)):
        t_full = np.arange(1, len(traj.contour_mm) + 1) * config.sample_period_s
        ax_f, ax_e = axes[0, col], axes[1, col]
        ax_f.plot(traj.t_s, traj.feed_mm_s, lw=1)
        ax_f.axhline(vmax, color="grey", ls="--", lw=0.8)
        ax_f.set_title(f"{rep['algorithm']}: {rep['motion_time_s']:.3f} s")
        ax_f.set_ylabel("feed (mm/s)")
        contour_um = np.where(traj.contouring, traj.contour_mm * 1000.0, np.nan)  # not on rapids
        ax_e.plot(t_full, contour_um, lw=1, color="tab:red")
        for sign in (1, -1):
            ax_e.axhline(sign * limit_um, color="grey", ls="--", lw=0.8)
        ax_e.set_ylabel("contour error (um)")
        ax_e.set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
