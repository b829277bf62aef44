"""Feed planner on the benchmark curves: planning time, planned duration, ratio to the bound."""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

from controller.generator.feed.limits import path_feed_limit_mm_s
from controller.generator.feed.planner import clear_memo, plan_feed
from controller.generator.feed.time_bound import time_optimal_bound_s

HERE = Path(__file__).resolve().parent


def _time_bound_bench():
    """bench/time_bound.py (its independent G6.2 reader and arc-length sampling)."""
    spec = importlib.util.spec_from_file_location("time_bound_bench", HERE / "time_bound.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--vmax", type=float, default=3500.0 / 60.0, help="mm/s")
    ap.add_argument("--amax", type=float, default=2450.0, help="mm/s^2")
    ap.add_argument("--period", type=float, default=0.001, help="s")
    ap.add_argument("--chord-tol", type=float, default=0.001, help="mm")
    ap.add_argument("--repeat", type=int, default=7, help="best-of timing runs")
    args = ap.parse_args(argv)
    bench = _time_bound_bench()
    for name, n in (("naca2415", 20_000), ("butterfly", 40_000)):
        s, kappa = bench.arc_length_samples(HERE.parent / "nc_programs" / f"{name}.nc", n)
        vlim = path_feed_limit_mm_s(kappa, args.period, args.chord_tol, args.amax, args.vmax)
        best = float("inf")
        for _ in range(args.repeat):
            clear_memo()  # from cold: the memo would otherwise serve every repeat
            t0 = time.perf_counter()
            plan = plan_feed(s, vlim, args.amax)
            best = min(best, time.perf_counter() - t0)
        bound = time_optimal_bound_s(s, kappa, args.vmax, args.amax, args.period, args.chord_tol)
        dur = plan.profile.duration_s
        print(f"{name}: grid {n}, {plan.result.name}, {len(plan.profile.phases)} phases, "
              f"{plan.rounds} round(s), plan {best * 1e3:.1f} ms; T = {dur:.4f} s, "
              f"bound {bound:.4f} s, ratio {dur / bound:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
