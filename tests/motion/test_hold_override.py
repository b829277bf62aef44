"""Feed hold, resume and feed override on the butterfly: on the path, within Amax and eps_max."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from runtime_helpers import virtual_card, xy_config

from controller.generator.plan import generate_reference
from controller.interpreter.program import read_program
from controller.motion.loop import MotionController
from controller.motion.pacing import VirtualPacer
from controller.motion.source import ChunkSource
from controller.motion.types import MotionProgress, MotionSettings, MotionState, Outcome
from controller.servo.model import discretise, tracking_error_mm
from controller.servo.path_distance import path_distance
from controller.servo.prediction import planning_limit_mm
from controller.servo.true_distance import distance_from_reference_mm

CFG = xy_config()
T = CFG.sample_period_s
VMAX = CFG.interpolator.max_feed_mm_s
AMAX = CFG.interpolator.max_accel_mm_s2
BUTTERFLY = Path(__file__).resolve().parents[2] / "nc_programs" / "butterfly.nc"


@cache
def butterfly_chunks(feed_mm_min: int = 3500) -> tuple:
    """The butterfly as programmed (F3500 = Vmax), or at a lower programmed feed."""
    path = BUTTERFLY
    if feed_mm_min != 3500:
        import tempfile
        tmp = Path(tempfile.mkdtemp()) / f"butterfly_f{feed_mm_min}.nc"
        tmp.write_text(BUTTERFLY.read_text().replace("F3500", f"F{feed_mm_min}"))
        path = tmp
    return tuple(generate_reference(read_program(str(path), CFG), CFG))


@dataclass
class Run:
    result: object
    sent: np.ndarray  # every reference row sent to the card, in order (XY)
    feed: np.ndarray  # the feed column sent with it
    seen: list[MotionProgress] = field(default_factory=list)
    changes: list[tuple[int, float]] = field(default_factory=list)  # (sent rows, override)
    recalled: int = 0  # frames the card gave back for a hold or a lower override


def run(events: list[tuple[float, str, float]], held_cycles: int = 20,
        when_held: tuple[str, float] = ("resume", 0.0), feed_mm_min: int = 3500) -> Run:
    """Run the butterfly in virtual time; events (executed time, 'hold' | 'feed', value) are
    given as the operator would; after `held_cycles` progress reports at a standstill,
    when_held is given: a resume, or a feed override."""
    card = virtual_card(CFG)
    settings = MotionSettings.from_config(CFG, progress_every_s=0.002)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    rows: list[tuple[int, np.ndarray]] = []
    pending = sorted(events)
    out = Run(None, np.zeros((0, 2)), np.zeros(0))

    def progress(p: MotionProgress) -> None:
        out.seen.append(p)
        while pending and p.executed_s >= pending[0][0]:
            _, what, value = pending.pop(0)
            if what == "hold":
                ctrl.request_hold()
            else:
                ctrl.set_feed_override(value)
                out.changes.append((ctrl.stream.sent, value))
        if p.state is MotionState.HELD and \
                sum(s.state is MotionState.HELD for s in out.seen) == held_cycles:
            if when_held[0] == "resume":
                ctrl.request_resume()
            else:
                ctrl.set_feed_override(when_held[1])

    ctrl = MotionController(CFG, card, ChunkSource(butterfly_chunks(feed_mm_min)), pacer,
                            settings, on_progress=progress)
    send = ctrl._send

    def recording_send(r: np.ndarray, end: bool, pause: bool = False) -> None:
        rows.append((ctrl.stream.sent, r.copy()))
        send(r, end, pause)

    ctrl._send = recording_send  # type: ignore[method-assign]
    out.result = ctrl.run()
    sent = as_executed(rows, ctrl.stream.sent)
    out.sent, out.feed = sent[:, :2], sent[:, 2]
    out.recalled = ctrl.stream.recalled_frames
    return out


def as_executed(sends: list, total: int) -> np.ndarray:
    """The rows the card ran: a hold takes queued frames back (Drive.recall_frames) and the
    loop sends others in their place, so a later send at the same frame number wins."""
    width = next(r.shape[1] for _, r in sends if len(r))
    out = np.zeros((total, width))
    for start, r in sends:
        n = max(0, min(len(r), total - start))
        out[start: start + n] = r[:n]
    return out


@cache
def plain() -> Run:
    return run([])


def speeds(xy: np.ndarray) -> np.ndarray:
    start = plain().sent[:1]
    return np.linalg.norm(np.diff(np.vstack([start, xy]), axis=0), axis=1) / T


def predicted_distance_mm(xy: np.ndarray) -> np.ndarray:
    """The servo model's distance of the tool from the points sent (the loop's own measure),
    with the settling after the last one."""
    held = np.vstack([xy, np.repeat(xy[-1:], 100, axis=0)])
    v = np.diff(held, axis=0, prepend=held[:1]) / T
    e = np.column_stack([tracking_error_mm(discretise(a.servo, T), v[:, i])
                         for i, a in enumerate(CFG.axes)])
    return distance_from_reference_mm(held, held - e)


def check_common(r: Run) -> None:
    base = plain()
    assert r.result.outcome is Outcome.DONE and r.result.underruns == 0, r.result.message
    assert r.result.final_position_mm == base.result.final_position_mm
    assert np.array_equal(r.sent[-1], base.sent[-1])  # the same end point, exactly
    v = speeds(r.sent)
    assert v.max() <= VMAX * (1 + 1e-9)  # no jump, never above Vmax
    assert np.abs(np.diff(v)).max() / T <= AMAX * (1 + 1e-6)  # tangential accel
    assert predicted_distance_mm(r.sent).max() <= planning_limit_mm(CFG) + 1e-9
    assert r.result.contour_error_um["max"] <= CFG.interpolator.contour_error_limit_mm * 1e3
    # The frames a hold takes back are replaced in the history the model watch runs on: the
    # card's own plant is still its model, to the encoder's quantisation.
    assert r.result.model_residual_um["max"] < 1.0 and r.result.model_warning is None
    # On the path: every point sent lies on the plan's polyline, off it by no more than the
    # chord tolerance (points between rows follow the curve, outside the chords).
    gap_mm = path_distance(base.sent, r.sent).distance_mm.max()
    assert gap_mm < CFG.interpolator.chord_tolerance_mm


def hold_times() -> list[float]:
    """Ten hold points: cruise, decelerations, inside corners (feed minima), accelerations."""
    feed = plain().feed
    a = np.diff(feed) / T
    minima = [k for k in range(1, len(feed) - 1)
              if feed[k] < feed[k - 1] and feed[k] <= feed[k + 1] and feed[k] < 0.5 * VMAX]
    decel = np.flatnonzero(a[:-500] < -0.5 * AMAX)  # not the final stop: it ends the program
    accel = np.flatnonzero(a > 0.5 * AMAX)
    picks = [minima[0], minima[len(minima) // 2], minima[-1], decel[0], decel[len(decel) // 2],
             decel[-1], accel[len(accel) // 2], 300, 2500, len(feed) - 400]
    return [k * T for k in picks]


@pytest.mark.parametrize("k", range(10))
def test_hold_and_resume_stay_on_the_path_within_the_limits(k: int) -> None:
    at_s = hold_times()[k]
    r = run([(at_s, "hold", 0.0)])
    check_common(r)
    states = [s.state for s in r.seen]
    assert MotionState.HELD in states
    held = [s for s in r.seen if s.state is MotionState.HELD]
    assert all(s.feed_mm_s == 0.0 and s.fifo_ms == 0.0 for s in held)
    # The held position is on the path (a point of the plan's polyline, within a micrometre).
    p = np.array(held[-1].position_mm)
    gap = distance_from_reference_mm(plain().sent, np.repeat(p[None, :], len(plain().sent), 0))
    assert gap.min() < 0.03
    # It stopped: several samples at exactly the same point in the reference sent.
    v = speeds(r.sent)
    assert np.any(v == 0.0)
    assert r.recalled > 0  # the frames queued beyond the low-water mark were taken back


def test_override_steps_keep_feed_accel_and_contour_limits() -> None:
    events = [(0.8, "feed", 30.0), (2.5, "feed", 150.0), (4.0, "feed", 100.0)]
    r = run(events)
    check_common(r)
    v = speeds(r.sent)
    # Once a step has taken effect (card FIFO latency plus the ramp), feed <= override x plan.
    settle_rows = int(0.4 / T)
    (k30, _), (k150, _), _ = r.changes
    # (1e-4: between rows the points follow the curve, a ripple of 1e-5 in speed)
    assert v[k30 + settle_rows: k150].max() <= 0.3 * VMAX * (1 + 1e-4)
    assert np.allclose(v[k30 + settle_rows: k150].max(), 0.3 * VMAX, rtol=0.02)
    assert r.result.motion_time_s > plain().result.motion_time_s + 1.0
    assert all(s.override_pct in (100.0, 30.0, 150.0) for s in r.seen)


def test_override_above_100_speeds_up_within_every_limit() -> None:
    """Programmed at F1500 (25 mm/s), below Vmax: 150 % runs at 37.5 mm/s where the rows ahead
    allow it, and back to the plan where Vmax, Amax or the contour limit would break."""
    plan = run([], feed_mm_min=1500)
    r = run([(0.5, "feed", 30.0), (2.0, "feed", 150.0), (9.0, "feed", 100.0)],
            feed_mm_min=1500)
    assert r.result.outcome is Outcome.DONE and r.result.underruns == 0
    assert r.result.final_position_mm == plan.result.final_position_mm
    v = speeds(r.sent)
    assert v.max() <= 1.5 * 25.0 * (1 + 1e-4)  # feed <= override x programmed
    assert v.max() >= 1.5 * 25.0 * (1 - 1e-3)  # and it did go faster than programmed
    assert np.abs(np.diff(v)).max() / T <= AMAX * (1 + 1e-6)
    assert predicted_distance_mm(r.sent).max() <= planning_limit_mm(CFG) + 1e-9
    assert r.result.contour_error_um["max"] <= CFG.interpolator.contour_error_limit_mm * 1e3
    assert path_distance(plan.sent, r.sent).distance_mm.max() < \
        CFG.interpolator.chord_tolerance_mm


def test_zero_override_is_a_hold_until_turned_up() -> None:
    r = run([(1.0, "feed", 0.0)], when_held=("feed", 100.0))
    check_common(r)
    assert np.any(speeds(r.sent) == 0.0)
    assert any(s.state is MotionState.HELD and s.override_pct == 0.0 for s in r.seen)


def test_abort_while_held_ends_at_rest_where_it_stood() -> None:
    card = virtual_card(CFG)
    settings = MotionSettings.from_config(CFG, progress_every_s=0.002)
    pacer = VirtualPacer(settings.cycle_frames, T, card.advance)
    seen: list[MotionProgress] = []

    def progress(p: MotionProgress) -> None:
        seen.append(p)
        if p.executed_s >= 1.0 and len(seen) and not getattr(ctrl, "_held", False):
            ctrl._held = True  # type: ignore[attr-defined]
            ctrl.request_hold()
        if p.state is MotionState.HELD and sum(s.state is MotionState.HELD for s in seen) == 5:
            ctrl.request_abort()

    ctrl = MotionController(CFG, card, ChunkSource(butterfly_chunks()), pacer, settings,
                            on_progress=progress)
    result = ctrl.run()
    assert result.outcome is Outcome.ABORTED
    held = [s for s in seen if s.state is MotionState.HELD][-1]
    final = np.array(list(result.final_position_mm.values()))
    stood = card.position_counts()[0] * CFG.axes[0].pulse_mm  # the step counter: held point
    assert np.allclose(final, stood, atol=1e-9)  # settled on the held point, no motion after
    assert np.abs(final - held.position_mm).max() < 0.01  # (the tool was still settling)
    assert result.commanded_counts == result.executed_counts


def test_m49_runs_its_lines_at_100_percent_whatever_the_override(tmp_path: Path) -> None:
    from controller.offsets import ProgramOffsets
    program = tmp_path / "m49.nc"
    program.write_text("G21 G90 G61 F1200\nG1 X20\nM49\nG1 Y20\nM48\nG1 X0\nM2\n")
    track = ProgramOffsets()
    chunks = tuple(generate_reference(read_program(str(program), CFG, track=track), CFG))
    assert track.override_off_lines == [[3, 5]]
    card = virtual_card(CFG)
    settings = MotionSettings.from_config(CFG)
    ctrl = MotionController(CFG, card, ChunkSource(chunks), VirtualPacer(2, T, card.advance),
                            settings)
    ctrl.set_override_off_lines(track.override_off_lines)
    ctrl.set_feed_override(50.0)
    rows: list[tuple[int, np.ndarray]] = []
    send = ctrl._send

    def record(r: np.ndarray, end: bool, pause: bool = False) -> None:
        rows.append((ctrl.stream.sent, r.copy()))
        send(r, end, pause)
    ctrl._send = record  # type: ignore[method-assign]
    result = ctrl.run()
    assert result.outcome is Outcome.DONE
    sent = as_executed(rows, ctrl.stream.sent)
    v = np.linalg.norm(np.diff(sent[:, :2], axis=0), axis=1) / T
    line = np.floor(np.abs(sent[1:, -1])).astype(int)
    assert np.isclose(v[line == 2].max(), 10.0, rtol=1e-3)  # 50 % of F1200
    assert np.isclose(v[line == 4].max(), 20.0, rtol=1e-3)  # M49: the programmed feed
    assert np.isclose(v[line == 6].max(), 10.0, rtol=1e-3)
