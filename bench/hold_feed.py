"""Feed hold and feed override: time and distance to a standstill against the physical minimum
at Amax, and the latency from a `feed` change to the new feed (docs/results.md gives them).

Runs the motion controller on the virtual sim card (the same loop `cncctl run` uses) with the
planned reference of a program, asks for a hold at points spread over it (or an override
step), and reads the reference rows actually sent to the card:

    python bench/hold_feed.py [--program nc_programs/butterfly.nc] [--points 10] [--markdown]
                              [--config xy_table_paper]

With servo pre-compensation the rows read are the wanted ones (before the lead is added); the
frames the loop adds at a standstill for the lead to die away hold the wanted point.

The physical minimum from feed v is a stop at constant deceleration Amax: v / Amax seconds over
v^2 / (2 Amax) mm. Ours adds the card FIFO already filled (frames queued cannot be recalled:
the decel starts behind them), and a jerk-limited ramp whose length the contour check sets.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from controller.config import load_config  # noqa: E402
from controller.generator.plan import generate_reference  # noqa: E402
from controller.interpreter.program import read_program  # noqa: E402
from controller.motion.loop import MotionController  # noqa: E402
from controller.motion.pacing import VirtualPacer  # noqa: E402
from controller.motion.source import ChunkSource  # noqa: E402
from controller.motion.types import MotionProgress, MotionSettings, MotionState  # noqa: E402
from drivers.sim.card import SimCard  # noqa: E402

CFG = load_config("xy_table")
T = CFG.sample_period_s
AMAX = CFG.interpolator.max_accel_mm_s2


def run(chunks: tuple, at_s: float, action: str, value: float = 0.0) -> dict:
    """One run; the action at executed time at_s. Returns the rows sent and when it acted."""
    card = SimCard(CFG, realtime=False)
    card.open()
    settings = MotionSettings.from_config(CFG, progress_every_s=T)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    sent: list[tuple[int, np.ndarray]] = []
    info: dict = {"held_reports": 0}

    def progress(p: MotionProgress) -> None:
        if "asked_at" not in info and p.executed_s >= at_s:
            info["asked_at"] = int(round(p.executed_s / T))  # executed frames so far
            info["queued"] = int(round(p.fifo_ms * 1e-3 / T))
            if action == "hold":
                ctrl.request_hold()
            else:
                ctrl.set_feed_override(value)
        if p.state is MotionState.HELD:
            info["held_reports"] += 1
            if info["held_reports"] == 3:
                ctrl.request_resume()

    ctrl = MotionController(CFG, card, ChunkSource(chunks), pacer, settings,
                            on_progress=progress)
    send = ctrl._send

    def record(rows: np.ndarray, end: bool, pause: bool = False) -> None:
        sent.append((ctrl.sent, rows[:, :2].copy()))
        send(rows, end, pause)
    ctrl._send = record  # type: ignore[method-assign]
    ctrl.run()
    card.close()
    # The rows the card ran: frames taken back for a hold are replaced by later sends; frames
    # no send recorded (a pre-compensated standstill's settling) hold the row before them.
    xy = np.full((ctrl.sent, 2), np.nan)
    for start, rows in sent:
        n = max(0, min(len(rows), ctrl.sent - start))
        xy[start: start + n] = rows[:n]
    for k in np.flatnonzero(np.isnan(xy[:, 0])):
        xy[k] = xy[k - 1]
    info["xy"] = xy
    info["recalled"] = ctrl.recalled_frames
    return info


def speeds(xy: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(xy, axis=0, prepend=xy[:1]), axis=1) / T


def hold_figures(chunks: tuple, at_s: float) -> dict:
    info = run(chunks, at_s, "hold")
    v = speeds(info["xy"])
    k0 = info["asked_at"]
    v0 = float(v[k0])
    rest = k0 + int(np.flatnonzero(v[k0:] == 0.0)[0])
    step = np.linalg.norm(np.diff(info["xy"], axis=0), axis=1)
    dist = float(step[k0:rest].sum())
    return {"at_s": at_s, "v0": v0, "t_s": (rest - k0) * T, "d_mm": dist,
            "t_min_s": v0 / AMAX, "d_min_mm": v0 * v0 / (2 * AMAX),
            "fifo_ms": info["queued"] * T * 1e3, "recalled_ms": info["recalled"] * T * 1e3}


def arc_mm(xy: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])


def feed_latency(chunks: tuple, at_s: float, percent: float) -> dict:
    """Frames from the request until the reference first leaves the plan, and until its feed
    is within 1 % of percent x the plan's feed at the same point of the path."""
    plain_xy = run(chunks, 1e9, "feed", 100.0)["xy"]
    info = run(chunks, at_s, "feed", percent)
    v, xy = speeds(info["xy"]), info["xy"]
    k0 = info["asked_at"]
    n = min(len(xy), len(plain_xy))
    moved = np.linalg.norm(xy[k0:n] - plain_xy[k0:n], axis=1) > 1e-9
    differs = k0 + int(np.flatnonzero(moved)[0])
    target = percent / 100.0 * np.interp(arc_mm(xy), arc_mm(plain_xy), speeds(plain_xy))
    close = np.abs(v - target) <= 0.01 * np.maximum(target, 1e-9)
    reached = differs + int(np.flatnonzero(close[differs:])[0])
    return {"at_s": at_s, "first_change_ms": (differs - k0) * T * 1e3,
            "settled_ms": (reached - k0) * T * 1e3, "fifo_ms": info["queued"] * T * 1e3}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--program", default=str(REPO / "nc_programs/butterfly.nc"))
    ap.add_argument("--points", type=int, default=10)
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--config", help="machine configuration (default: xy_table)")
    args = ap.parse_args()
    global CFG, T, AMAX
    CFG = load_config(args.config or "xy_table")
    T, AMAX = CFG.sample_period_s, CFG.interpolator.max_accel_mm_s2
    chunks = tuple(generate_reference(read_program(args.program, CFG), CFG))
    total_s = sum(len(c) for c in chunks) * T
    times = np.linspace(0.1, total_s - 0.4, args.points)
    holds = [hold_figures(chunks, float(t)) for t in times]
    print(f"{Path(args.program).name}: feed hold at {args.points} points (virtual time, "
          f"Amax {AMAX:g} mm/s^2, card FIFO high water {CFG.runtime.card_fifo_high_water_ms:g} "
          "ms)\n")
    head = ["at t (s)", "feed (mm/s)", "to standstill (ms)", "minimum (ms)", "distance (mm)",
            "minimum (mm)", "card FIFO (ms)", "taken back (ms)"]
    print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    for h in holds:
        print(f"| {h['at_s']:.2f} | {h['v0']:.1f} | {h['t_s'] * 1e3:.0f} | "
              f"{h['t_min_s'] * 1e3:.1f} | {h['d_mm']:.2f} | {h['d_min_mm']:.3f} | "
              f"{h['fifo_ms']:.0f} | {h['recalled_ms']:.0f} |")
    ratio_t = [h["t_s"] / h["t_min_s"] for h in holds if h["t_min_s"] > 0]
    print(f"\nmedian time to standstill {statistics.median(h['t_s'] for h in holds) * 1e3:.0f}"
          f" ms; median ratio to the minimum {statistics.median(ratio_t):.1f}")
    lat = [feed_latency(chunks, float(t), 30.0) for t in times[1:-1:2]]
    print("\nfeed 100 -> 30 %: latency from the request\n")
    print("| at t (s) | first change (ms) | within 1 % of 30 % (ms) | card FIFO (ms) |\n"
          "|---|---|---|---|")
    for f in lat:
        print(f"| {f['at_s']:.2f} | {f['first_change_ms']:.0f} | {f['settled_ms']:.0f} | "
              f"{f['fifo_ms']:.0f} |")


if __name__ == "__main__":
    main()
