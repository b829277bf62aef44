"""Parser benchmark: lines per second and peak RSS for a generated 1,000,000-line G1/G2/G3 program.

Usage: python bench/parse.py [--lines N] [--config NAME]   (target: >= 100,000 lines/s, < 150 MB)
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import tempfile
import time

from controller.config import load_config
from controller.interpreter.program import read_program
from controller.operator.check_cmd import check_program


def write_program(path: str, n_lines: int) -> None:
    """A stream of G1 segments and G2/G3 arcs (I J and R forms) around a 100 mm circle."""
    with open(path, "w", encoding="ascii") as f:
        f.write("G17 G21 G90 G64 P0.01\nF3000\nG0 X50 Y0\n")
        r = 50.0
        step = 2 * math.pi / 3600
        for i in range(n_lines - 4):
            a = (i + 1) * step
            x, y = r * math.cos(a), r * math.sin(a)
            kind = i % 4
            if kind == 0:
                f.write(f"G1 X{x:.4f} Y{y:.4f}\n")
            elif kind == 1:  # counter-clockwise arc about the origin, centre as I J offsets
                pa = i * step
                f.write(f"G3 X{x:.4f} Y{y:.4f} I{-r * math.cos(pa):.4f} J{-r * math.sin(pa):.4f}\n")
            elif kind == 2:
                f.write(f"G3 X{x:.4f} Y{y:.4f} R{r:.4f}\n")
            else:
                f.write(f"N{i} G1 X{x:.4f} Y{y:.4f} F{3000 + (i % 7)}\n")
        f.write("M2\n")


def peak_rss_mb() -> float:
    """Peak resident set size of this process (ru_maxrss is kB on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024 * 1024) if sys.platform == "darwin" else peak / 1024


def report(what: str, lines: int, blocks: int, t0: float, c0: float) -> None:
    # CPU time is quoted too: on a shared machine the wall-clock rate includes other jobs.
    wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    print(f"{what}: {lines} lines, {blocks} blocks, wall {wall_s:.2f} s, CPU {cpu_s:.2f} s: "
          f"{lines / wall_s:,.0f} lines/s wall, {lines / cpu_s:,.0f} lines/s CPU "
          f"(target >= 100,000)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--lines", type=int, default=1_000_000)
    parser.add_argument("--config", default="xy_table")
    args = parser.parse_args(argv)
    config = load_config(args.config)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.nc")
        write_program(path, args.lines)
        rss_before_mb = peak_rss_mb()
        t0, c0 = time.perf_counter(), time.process_time()
        blocks = sum(1 for _ in read_program(path, config))
        report("read_program", args.lines, blocks, t0, c0)
        t0, c0 = time.perf_counter(), time.process_time()
        summary = check_program(path, config)
        report("cncctl check", args.lines, sum(summary.blocks.values()), t0, c0)
    print(f"peak RSS: {peak_rss_mb():.1f} MB  (before parsing {rss_before_mb:.1f} MB; "
          f"target < 150 MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
