"""PNG plot for `cncctl inspect`: the path with corner zones and PH segments, and kappa(u)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from controller.operator.inspect_report import InspectReport
from controller.operator.outputs import plot_format

if TYPE_CHECKING:
    from matplotlib.figure import Figure

_SAMPLES_PER_SPAN = 32


def plot_report(report: InspectReport, png_path: str) -> None:
    import matplotlib.pyplot as plt

    fig = draw_report(report)
    fig.savefig(png_path, dpi=110, format=plot_format(png_path))
    plt.close(fig)


def draw_report(report: InspectReport) -> Figure:
    """The figure: every block's path on the left (lines, arcs, NURBS), kappa(u) on the right."""
    import matplotlib

    matplotlib.use("Agg")  # no display needed
    import matplotlib.pyplot as plt

    fig, (ax_path, ax_kappa) = plt.subplots(1, 2, figsize=(13, 5.5))
    feed_label, rapid_label = "lines and arcs", "rapids"
    for pts, rapid in report.moves:
        ax_path.plot(pts[:, 0], pts[:, 1], ":" if rapid else "-", color="0.45", lw=0.8,
                     label=rapid_label if rapid else feed_label)
        feed_label, rapid_label = (feed_label, None) if rapid else (None, rapid_label)
    for i, (curve, zones, segments, kappa_th) in enumerate(
            zip(report.curves, report.zones, report.segments, report.kappa_th_per_mm,
                strict=True)):
        spans = np.unique(curve.knots)
        u = np.unique(np.concatenate([np.linspace(a, b, _SAMPLES_PER_SPAN)
                                      for a, b in zip(spans[:-1], spans[1:], strict=True)]))
        pts = curve.evaluate(u, 0)[0]
        ax_path.plot(pts[:, 0], pts[:, 1], "k-", lw=0.8, label="NURBS" if i == 0 else None)
        for j, z in enumerate(zones):
            uz = np.linspace(z.u_start, z.u_end, 100)
            pz = curve.evaluate(uz, 0)[0]
            ax_path.plot(pz[:, 0], pz[:, 1], "r-", lw=4, alpha=0.35,
                         label="corner zone" if i == j == 0 else None)
            ax_kappa.axvspan(z.u_start, z.u_end, color="r", alpha=0.15)
        for j, seg in enumerate(segments):
            z = seg.ph.point(np.linspace(0, 1, 60))
            ax_path.plot(z.real, z.imag, "b-", lw=1.2, label="PH quintics" if i == j == 0 else None)
            ax_path.plot(z.real[[0, -1]], z.imag[[0, -1]], "b|", ms=8)
        ax_kappa.semilogy(u, np.maximum(curve.curvature(u), 1e-6), lw=0.8,
                          label=f"kappa(u), block {report.nurbs[i].line}")
        ax_kappa.axhline(kappa_th, color="r", ls="--", lw=0.8,
                         label="kappa_th" if i == 0 else None)
    ax_path.set_aspect("equal")
    ax_path.set_xlabel("X mm")
    ax_path.set_ylabel("Y mm")
    ax_path.legend(loc="best", fontsize=8)
    ax_kappa.set_xlabel("u")
    ax_kappa.set_ylabel("curvature 1/mm")
    if report.curves:
        ax_kappa.legend(loc="best", fontsize=8)
    else:
        ax_kappa.text(0.5, 0.5, "no NURBS blocks", ha="center", va="center",
                      transform=ax_kappa.transAxes)
    fig.tight_layout()
    return fig
