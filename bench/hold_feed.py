"""Feed hold and feed override: time and distance until the tool is at rest against the physical
minimum at Amax, and the latency from a `feed` change to the new feed (docs/results.md gives them).

Runs the motion controller on the virtual sim card (the same loop `cncctl run` uses) with the
planned reference of a program and asks for a hold at points spread over it (or an override
step). The hold is measured on the tool: the servo model of each axis (eq. 27, the plant the
card runs) driven by the step counters the card actually clocked, frames taken back excluded
and the pre-compensation's lead included:

    python bench/hold_feed.py [--program nc_programs/butterfly.nc] [--points 10] [--markdown]
                              [--config xy_table_paper] [--holds-only] [--hold-fall SHARE]
    python bench/hold_feed.py --floor [--hold-fall SHARE] [--stretch K]

--floor prints what the servo model alone takes after a hold's ramp, by speed (model_floor).

The tool is at rest from the first period after which it moves less than REST_STEP_MM a period
and stays within REST_BAND_MM of where the hold leaves it. The physical minimum from tool
speed v is a stop at constant deceleration Amax: v / Amax seconds over v^2 / (2 Amax) mm. The
contour column is the tool's largest distance from the planned path over the hold.
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
from controller.motion import hold_ramp  # noqa: E402
from controller.motion.hold_ramp import hold_distances_mm, hold_shape  # noqa: E402
from controller.motion.loop import MotionController  # noqa: E402
from controller.motion.pacing import VirtualPacer  # noqa: E402
from controller.motion.source import ChunkSource  # noqa: E402
from controller.motion.types import MotionProgress, MotionSettings, MotionState  # noqa: E402
from controller.servo.model import discretise, filter_block  # noqa: E402
from controller.servo.path_distance import path_distance  # noqa: E402
from controller.servo.precompensation import compensation_filter  # noqa: E402
from controller.servo.prediction import plant_servos, rest_state  # noqa: E402
from drivers.sim.card import SimCard  # noqa: E402

CFG = load_config("xy_table")
T = CFG.sample_period_s
AMAX = CFG.interpolator.max_accel_mm_s2
REST_STEP_MM = 1e-3  # at rest: under 1 um a period ...
REST_BAND_MM = 1e-3  # ... and staying within 1 um of where it stops
# Within two pulses: the tool's float position driven by whole pulses wanders about its final
# point by the quantisation (the frames rounded to 1 um, the final point a whole pulse), while
# the pre-compensation's lead dies away pulse by pulse (a single pulse moves the model's tool
# about 1 um in that period). This criterion ignores that wander; the one above does not.
QUANT_BAND_MM = 2e-3
HELD_S = 0.3  # the hold is resumed this long after the loop reports HELD
# Holds at this share of the fastest one or more are summed up apart: a slower hold's minimum
# (v / Amax) is short beside what every hold takes whatever its speed (the request reaching
# the card, the servo settling), so its ratio says little about the ramp.
FAST_SHARE = 0.9


def run(chunks: tuple, at_s: float, action: str, value: float = 0.0) -> dict:
    """One run; the action at executed time at_s. Returns the rows sent (wanted path), the
    step counters the card clocked each period, and when it acted."""
    card = SimCard(CFG, realtime=False)
    card.open()
    settings = MotionSettings.from_config(CFG, progress_every_s=T)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    sent: list[tuple[int, np.ndarray]] = []
    clocked: list[np.ndarray] = []
    info: dict = {"held_reports": 0}
    axes = card._axes  # noqa: SLF001 (the bench reads the simulated table's counters)
    step = axes.step

    def clock(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cmd, enc = step(frames)
        clocked.append(cmd[:, :2].copy())
        return cmd, enc
    axes.step = clock  # type: ignore[method-assign]

    def progress(p: MotionProgress) -> None:
        if "asked_at" not in info and p.executed_s >= at_s:
            info["asked_at"] = int(round(p.executed_s / T))  # executed frames so far
            info["asked_clock"] = card.frames_clocked
            info["queued"] = int(round(p.fifo_ms * 1e-3 / T))
            if action == "hold":
                ctrl.request_hold()
            else:
                ctrl.set_feed_override(value)
        if p.state is MotionState.HELD:
            info["held_reports"] += 1
            if info["held_reports"] == 1:
                info["held_clock"] = card.frames_clocked
            if info["held_reports"] == round(HELD_S / T):
                info["resume_clock"] = card.frames_clocked
                ctrl.request_resume()

    ctrl = MotionController(CFG, card, ChunkSource(chunks), pacer, settings,
                            on_progress=progress)
    send = ctrl._send

    def record(rows: np.ndarray, end: bool, pause: bool = False) -> None:
        start = ctrl.stream.sent
        if sent and "asked_at" in info and "ramp_start" not in info \
                and start < sent[-1][0] + len(sent[-1][1]):
            info["ramp_start"] = start  # frames were taken back: the ramp starts here
        if pause and "asked_at" in info and "ramp_end" not in info:
            # The hold's ramp at rest: the last row that moves (then rows at rest, settling).
            step = np.linalg.norm(np.diff(rows[:, :2], axis=0), axis=1)
            info["ramp_end"] = start + 1 + int(np.flatnonzero(np.r_[1.0, step] > 1e-9)[-1])
        sent.append((start, rows[:, :2].copy()))
        send(rows, end, pause)
    ctrl._send = record  # type: ignore[method-assign]
    ctrl.run()
    card.close()
    # The rows the card ran: frames taken back for a hold are replaced by later sends; frames
    # no send recorded (a pre-compensated standstill's settling) hold the row before them.
    xy = np.full((ctrl.stream.sent, 2), np.nan)
    for start, rows in sent:
        n = max(0, min(len(rows), ctrl.stream.sent - start))
        xy[start: start + n] = rows[:n]
    for k in np.flatnonzero(np.isnan(xy[:, 0])):
        xy[k] = xy[k - 1]
    info["xy"] = xy
    info["cmd_mm"] = np.vstack(clocked) * np.array([a.pulse_mm for a in CFG.axes[:2]])
    info["recalled"] = ctrl.stream.recalled_frames
    return info


def tool_mm(cmd_mm: np.ndarray) -> np.ndarray:
    """The servo model's tool position each period, from the step counters clocked (the card
    starts at rest at the first)."""
    v = np.diff(cmd_mm, axis=0, prepend=cmd_mm[:1]) / T
    servos = plant_servos(CFG)
    sx, sy = rest_state(servos)
    err = np.column_stack([filter_block(servos[0], v[:, 0], sx)[0],
                           filter_block(servos[1], v[:, 1], sy)[0]])
    return cmd_mm - err


def rest_after(tool: np.ndarray, k0: int, k1: int, step_mm: float = REST_STEP_MM,
               band_mm: float = REST_BAND_MM) -> int:
    """The first period in k0..k1 from which the tool moves less than step_mm a period and
    stays within band_mm of where it is at k1."""
    seg = tool[k0: k1 + 1]
    step = np.linalg.norm(np.diff(seg, axis=0, prepend=seg[:1]), axis=1)
    off = np.linalg.norm(seg - seg[-1], axis=1)
    moving = np.flatnonzero((step >= step_mm) | (off > band_mm))
    return k0 + (int(moving[-1]) + 1 if moving.size else 0)


def speeds(xy: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(xy, axis=0, prepend=xy[:1]), axis=1) / T


def hold_figures(chunks: tuple, at_s: float, path_xy: np.ndarray) -> dict:
    info = run(chunks, at_s, "hold")
    tool = tool_mm(info["cmd_mm"])
    k0, k1 = info["asked_clock"], info["resume_clock"]
    rest = rest_after(tool, k0, k1)
    within = rest_after(tool, k0, k1, QUANT_BAND_MM, QUANT_BAND_MM)
    step = np.linalg.norm(np.diff(tool, axis=0), axis=1)
    v0 = float(step[k0 - 1]) / T
    near = path_distance(path_xy, tool[k0: k1 + 1]).distance_mm
    return {"at_s": at_s, "v0": v0, "t_s": (rest - k0) * T, "t_band_s": (within - k0) * T,
            "d_mm": float(step[k0:rest].sum()),
            "t_min_s": v0 / AMAX, "d_min_mm": v0 * v0 / (2 * AMAX),
            "contour_um": float(near.max()) * 1e3,
            "fifo_ms": info["queued"] * T * 1e3, "recalled_ms": info["recalled"] * T * 1e3,
            "ramp_from_ms": (info.get("ramp_start", info["asked_at"]) - info["asked_at"]) * T * 1e3,
            "ramp_to_ms": (info.get("ramp_end", info["asked_at"]) - info["asked_at"]) * T * 1e3}


def model_floor(v0_mm_s: float, stretch: float = 1.0) -> tuple[int, float, float]:
    """A hold from v0 on a straight line of the X axis without pulses: the hold's ramp (its
    samples), then when the servo model, driven by the pre-compensated frames (unrounded),
    is within QUANT_BAND_MM and REST_BAND_MM of the hold point for good, from the ramp's start
    (ms). What a hold takes at least once its ramp has reached the card."""
    servo = CFG.axes[0].servo
    shape = hold_shape(CFG.interpolator.ramp_share)
    dist = hold_distances_mm(v0_mm_s, AMAX, T, shape, stretch)
    lead_in = 400  # samples at v0 before the ramp: every filter at its steady state
    wanted = np.concatenate([np.arange(-lead_in, 1) * v0_mm_s * T, dist,
                             np.full(400, dist[-1])])
    v = np.diff(wanted, prepend=wanted[0] - v0_mm_s * T) / T
    frames = wanted
    if CFG.interpolator.servo_precompensation:
        comp = compensation_filter(servo, T)
        warm = filter_block(comp, np.full(lead_in, v0_mm_s), np.zeros(comp.order))[1]
        frames = wanted + filter_block(comp, v, warm)[0]
    plant = discretise(servo, T)
    warm = filter_block(plant, np.full(lead_in, v0_mm_s), np.zeros(plant.order))[1]
    tool = frames - filter_block(plant, np.diff(frames, prepend=frames[0] - v0_mm_s * T) / T,
                                 warm)[0]
    off = np.abs(tool - dist[-1])

    def settled_ms(band_mm: float) -> float:
        return (int(np.flatnonzero(off > band_mm)[-1]) + 1 - lead_in) * T * 1e3

    return len(dist), settled_ms(QUANT_BAND_MM), settled_ms(REST_BAND_MM)


def print_floor(stretch: float) -> None:
    print("| tool speed (mm/s) | minimum (ms) | 2 x minimum (ms) | ramp (ms) | "
          "within 2 um after the ramp's start (ms) | within 1 um (ms) |\n|---|---|---|---|---|---|")
    for v0 in (10.0, 20.0, 30.0, 40.0, 50.0, 58.0):
        n, band_ms, rest_ms = model_floor(v0, stretch)
        print(f"| {v0:.0f} | {v0 / AMAX * 1e3:.1f} | {2 * v0 / AMAX * 1e3:.1f} | {n * T * 1e3:.0f} "
              f"| {band_ms:.0f} | {rest_ms:.0f} |")


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


def _spread(t_s: list[float]) -> str:
    return (f"median {statistics.median(t_s) * 1e3:.1f} ms ({min(t_s) * 1e3:.0f}-"
            f"{max(t_s) * 1e3:.0f})")


def _ratios(r: list[float]) -> str:
    return f"{statistics.median(r):.2f} x the minimum (worst {max(r):.2f} x)"


def _summary(holds: list[dict]) -> str:
    ratio_t = [h["t_s"] / h["t_min_s"] for h in holds if h["t_min_s"] > 0]
    band_t = [h["t_band_s"] / h["t_min_s"] for h in holds if h["t_min_s"] > 0]
    return (f"tool at rest {_spread([h['t_s'] for h in holds])}, {_ratios(ratio_t)}; "
            f"within 2 um {_spread([h['t_band_s'] for h in holds])}, {_ratios(band_t)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--program", default=str(REPO / "nc_programs/butterfly.nc"))
    ap.add_argument("--points", type=int, default=10)
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--config", help="machine configuration (default: xy_table)")
    ap.add_argument("--holds-only", action="store_true", help="no feed override latency")
    ap.add_argument("--floor", action="store_true",
                    help="only the servo model's settling after a hold's ramp, by speed")
    ap.add_argument("--hold-fall", type=float,
                    help="the hold's ramp falls over this share of it (default: the shipped "
                         f"{hold_ramp.HOLD_FALL_SHARE:g})")
    ap.add_argument("--stretch", type=float, default=1.0,
                    help="with --floor: the hold's ramp this many times longer")
    args = ap.parse_args()
    if args.hold_fall is not None:
        hold_ramp.HOLD_FALL_SHARE = args.hold_fall  # hold_shape() reads it for each run
    global CFG, T, AMAX
    CFG = load_config(args.config or "xy_table")
    T, AMAX = CFG.sample_period_s, CFG.interpolator.max_accel_mm_s2
    if args.floor:
        print_floor(args.stretch)
        return
    chunks = tuple(generate_reference(read_program(args.program, CFG), CFG))
    total_s = sum(len(c) for c in chunks) * T
    times = np.linspace(0.1, total_s - 0.4, args.points)
    path_xy = np.vstack([c.pos_mm[:, :2] for c in chunks])
    holds = [hold_figures(chunks, float(t), path_xy) for t in times]
    print(f"{Path(args.program).name}: feed hold at {args.points} points, on the tool (virtual "
          f"time, Amax {AMAX:g} mm/s^2, card FIFO high water "
          f"{CFG.runtime.card_fifo_high_water_ms:g} ms)\n")
    head = ["at t (s)", "tool speed (mm/s)", "tool at rest (ms)", "within 2 um (ms)",
            "minimum (ms)", "ramp (ms)",
            "distance (mm)", "minimum (mm)", "contour (um)", "card FIFO (ms)",
            "taken back (ms)"]
    print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    for h in holds:
        print(f"| {h['at_s']:.2f} | {h['v0']:.1f} | {h['t_s'] * 1e3:.0f} | "
              f"{h['t_band_s'] * 1e3:.0f} | "
              f"{h['t_min_s'] * 1e3:.1f} | {h['ramp_from_ms']:.0f}-{h['ramp_to_ms']:.0f} | "
              f"{h['d_mm']:.2f} | {h['d_min_mm']:.3f} | "
              f"{h['contour_um']:.1f} | {h['fifo_ms']:.0f} | {h['recalled_ms']:.0f} |")
    print(f"\nall holds: {_summary(holds)}; "
          f"contour worst {max(h['contour_um'] for h in holds):.1f} um")
    top = max(h["v0"] for h in holds)
    fast = [h for h in holds if h["v0"] >= FAST_SHARE * top]
    if len(fast) < len(holds):
        print(f"at {FAST_SHARE:.0%} of the top speed or more ({len(fast)} holds): "
              f"{_summary(fast)}")
    if args.holds_only:
        return
    lat = [feed_latency(chunks, float(t), 30.0) for t in times[1:-1:2]]
    print("\nfeed 100 -> 30 %: latency from the request\n")
    print("| at t (s) | first change (ms) | within 1 % of 30 % (ms) | card FIFO (ms) |\n"
          "|---|---|---|---|")
    for f in lat:
        print(f"| {f['at_s']:.2f} | {f['first_change_ms']:.0f} | {f['settled_ms']:.0f} | "
              f"{f['fifo_ms']:.0f} |")


if __name__ == "__main__":
    main()
