"""The reference-point generator: NC blocks in, one reference point per sample period out."""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np

from controller.blocks import (
    ArcBlock,
    DwellBlock,
    HelixBlock,
    LineBlock,
    NcBlock,
    NurbsBlock,
    OutputBlock,
    PathMode,
    ProbeBlock,
    StopBlock,
    StopKind,
)
from controller.config import MachineConfig
from controller.errors import PlanningError
from controller.generator.baselines import FORMULA_FEEDS, plan_formula_run
from controller.generator.feed.planner import plan_feed
from controller.generator.feed.shape import TransitionShape
from controller.generator.helix_move import helix_move
from controller.generator.long_blocks import chunk_bounds, contour_parts, nurbs_parts
from controller.generator.output_marks import SyncMark, output_mark, with_synced
from controller.generator.ph.construct import BlockCurve, block_curves
from controller.generator.repeats import Repeats
from controller.generator.replan import (
    NURBS_LOOKAHEAD,
    PH_LOOKAHEAD,
    Continuation,
    RunPlan,
    RunStatus,
    plan_contour_run,
)
from controller.generator.window import continuation_cut
from controller.refpoints import RefChunk

MAX_RUN_BLOCKS = 500  # baselines: a longer contour is planned in pieces, stopping between
IN_POSITION_S = 0.04  # wait at rest before the next move: the servo settles to 2 % in 32 ms
# ph-lookahead: new blocks per look-ahead window (cut and continued) ... Each window plans its
# last MIN_OVERLAP_MM again with the next one: on short G1 lines 200 blocks re-planned a fifth
# of every window, 500 a fourteenth (walk 10k: 1.81 -> 1.42 s of CPU, peak RSS 53 -> 63 MB).
# At most MAX_RUN_BLOCKS: a run that long is flushed (to rest) before its window would close.
WINDOW_BLOCKS = 500
# ... or fewer, once they add up to this nominal motion time (length / programmed feed): a
# window of NURBS blocks stays a bounded stretch of motion (memory and re-planning), however
# long each block is. Every program of nc_programs/ is under half of it (plans unchanged).
WINDOW_NOMINAL_S = 30.0
# The other algorithms' runs (no look-ahead windows) also stop before this much nominal motion
# piles up: 500 parts of a long block (long_blocks.py) would be 5000 s of samples.
MAX_RUN_NOMINAL_S = 120.0


class Algorithm(StrEnum):
    ADAPTIVE = "adaptive"  # Yeh & Hsu 2002: feed = min(Vmax, V_af)
    CURVATURE = "curvature"  # Zhiming et al. 2002: feed = V_cf
    NURBS_LOOKAHEAD = "nurbs-lookahead"  # Tsai et al. 2008
    PH_LOOKAHEAD = "ph-lookahead"  # this controller (the paper's algorithm)


@dataclass(frozen=True, eq=False, repr=False)
class PlannedStep:
    """One chunk of reference points and, for contour runs, how it was planned."""

    chunk: RefChunk
    run: RunPlan | None = None
    rapid: bool = False  # a G0 move (and its in-position wait): not part of any contour
    phi_rad: np.ndarray | None = None  # exact path tangent angle per sample, where known


def _pos_row(config: MachineConfig, xy: np.ndarray, z_mm: float) -> np.ndarray:
    if config.has_axis("z"):
        return np.column_stack([xy, np.full(len(xy), z_mm)])
    return xy


def _straight_move(block: LineBlock, config: MachineConfig,
                   t0_s: float) -> Iterator[tuple[RefChunk, bool]]:
    """A line that moves Z, or a rapid: its own quintic feed profile from rest to rest, in
    chunks of at most CHUNK_SAMPLES made as they are taken (a slow Z move of hours is never
    one array), each with whether it is the last."""
    start, end = np.array(block.start), np.array(block.end)
    if not config.has_axis("z"):
        start, end = start[:2], end[:2]
    length = float(np.linalg.norm(end - start))
    if length < 1e-9:
        return
    cap = config.interpolator.rapid_feed_mm_s if block.rapid else min(
        block.feed_mm_s, config.interpolator.max_feed_mm_s)
    plan = plan_feed(np.array([0.0, length]), np.array([cap, cap]),
                     config.interpolator.max_accel_mm_s2,
                     shape=TransitionShape(config.interpolator.ramp_share))
    T = config.sample_period_s  # noqa: N806
    k = max(int(np.ceil(plan.profile.duration_s / T - 1e-9)), 1)
    for i0, i1 in chunk_bounds(k):
        t = np.minimum(np.arange(i0 + 1, i1 + 1) * T, plan.profile.duration_s)
        s, v, _ = plan.profile.evaluate(t)
        pos = start + (s / length)[:, None] * (end - start)
        if i1 == k:
            pos[-1] = end
        line = np.full(len(pos), block.source.first_line, np.int32)
        yield RefChunk(t0_s + (i0 + 1) * T, pos, v, line), i1 == k


def _in_position_hold(last: PlannedStep, config: MachineConfig, t_s: float) -> PlannedStep:
    """IN_POSITION_S of samples holding the last step's end point."""
    k = int(round(IN_POSITION_S / config.sample_period_s))
    rows = np.repeat(last.chunk.pos_mm[-1:], k, axis=0)
    line = np.full(k, last.chunk.line[-1], np.int32)
    chunk = RefChunk(t_s + config.sample_period_s, rows, np.zeros(k), line)
    return PlannedStep(chunk, rapid=last.rapid)


def _dwell(block: DwellBlock, config: MachineConfig, t0_s: float) -> Iterator[RefChunk]:
    """The dwell's samples holding the position, in chunks of at most CHUNK_SAMPLES made as
    they are taken."""
    T = config.sample_period_s  # noqa: N806
    k = int(round(block.seconds / T))
    pos = np.array(block.position)[: len(config.axis_names)]
    for i0, i1 in chunk_bounds(k):
        rows = np.repeat(pos[None, :], i1 - i0, axis=0)
        yield RefChunk(t0_s + (i0 + 1) * T, rows, np.zeros(i1 - i0),
                       np.full(i1 - i0, block.source.first_line, np.int32))


def _pause(block: StopBlock, config: MachineConfig, t0_s: float) -> RefChunk:
    """IN_POSITION_S of samples holding the pause point, the program pausing after them."""
    k = int(round(IN_POSITION_S / config.sample_period_s))
    pos = np.repeat(np.array(block.position)[None, : len(config.axis_names)], k, axis=0)
    return RefChunk(t0_s + config.sample_period_s, pos, np.zeros(k),
                    np.full(k, block.source.first_line, np.int32), pause_after=True)


def plan_run(curves: list[BlockCurve], start_xy: np.ndarray, config: MachineConfig,
             algorithm: Algorithm, cont: Continuation | None = None,
             repeats: Repeats | None = None,
             ) -> tuple[RunPlan | None, np.ndarray, np.ndarray, np.ndarray]:
    """Plan one XY contour run with the chosen algorithm: (report, xy, feed, line)."""
    if algorithm in FORMULA_FEEDS:
        s = plan_formula_run(curves, config, algorithm.value)
        return None, s.xy_mm, s.v_mm_s, s.line
    settings = PH_LOOKAHEAD if algorithm == Algorithm.PH_LOOKAHEAD else NURBS_LOOKAHEAD
    run = plan_contour_run(curves, start_xy, config, settings, cont, repeats)
    return run, run.samples.xy_mm, run.samples.v_mm_s, run.samples.line


def _curves(blocks: list[NcBlock], config: MachineConfig,
            repeats: Repeats | None = None) -> list[BlockCurve]:
    ip = config.interpolator
    curves = block_curves(blocks, ip.max_feed_mm_s,  # type: ignore[arg-type]
                          ip.contour_error_limit_mm)
    return curves if repeats is None else [repeats.intern(c) for c in curves]


def _contour(blocks: list[NcBlock], config: MachineConfig, algorithm: Algorithm,
             t0_s: float, cont: Continuation | None = None,
             repeats: Repeats | None = None) -> PlannedStep | None:
    """Plan pending blocks (after a cut of the previous window, if any) all the way to rest;
    repeats only when they end a long program's windows (cont)."""
    repeats = repeats if cont is not None else None
    curves = _curves(blocks, config, repeats)
    if not curves and cont is None:
        return None
    start = np.array(blocks[0].start[:2]) if cont is None else cont.xy_mm
    end = blocks[-1].end if blocks else cont.end_mm  # type: ignore[union-attr]
    run, xy, v, line = plan_run(curves, start, config, algorithm, cont, repeats)
    return _run_step(xy, v, line, run, t0_s, config, end[2], end[:2])


def _run_step(xy: np.ndarray, v: np.ndarray, line: np.ndarray, run: RunPlan | None, t0_s: float,
              config: MachineConfig, z_mm: float,
              end_xy: tuple[float, ...] | None = None) -> PlannedStep:
    """Samples of a run (or its first part) as one chunk; end_xy, for a run to rest, replaces
    the last point by the programmed end point exactly, not a curve evaluation."""
    if end_xy is not None:
        # The plan's own end must be the programmed one: replacing a far-off last point would
        # be a jump of the reference in one sample (a NURBS whose arc-length inverse failed on
        # extreme knot spacing ended 10 mm short, and the jump went out).
        miss_mm = float(np.hypot(xy[-1][0] - end_xy[0], xy[-1][1] - end_xy[1]))
        if miss_mm > END_MISS_MM:
            raise PlanningError(f"line {int(line[-1])}: the plan ends {miss_mm:.4f} mm from the "
                                f"programmed end X{end_xy[0]:.4f} Y{end_xy[1]:.4f}")
        xy = xy.copy()
        xy[-1] = end_xy
    phi = None if run is None else run.samples.phi_rad[:len(xy)]
    chunk = RefChunk(t0_s + config.sample_period_s, _pos_row(config, xy, z_mm), v, line)
    return PlannedStep(chunk, run, phi_rad=phi)


def _window(blocks: list[NcBlock], config: MachineConfig, t0_s: float,
            cont: Continuation | None,
            repeats: Repeats) -> tuple[PlannedStep | None, Continuation | None]:
    """Plan a look-ahead window to rest, then keep only what precedes its last cruise sample
    before the overlap; the rest is planned again with the next blocks (no stop between).

    Without such a cruise sample the whole window is kept and the machine stops at its end."""
    curves = _curves(blocks, config, repeats)
    if not curves:  # nothing moves in XY (all blocks shorter than a micrometre): keep going
        return None, cont
    start = np.array(blocks[0].start[:2]) if cont is None else cont.xy_mm
    run = plan_contour_run(curves, start, config, PH_LOOKAHEAD, cont, repeats)
    cut = continuation_cut(run, curves[-1].blend_tolerance_mm, blocks[-1].end, config, cont)
    end, s = blocks[-1].end, run.samples
    if cut is None or run.status != RunStatus.OK:
        return _run_step(s.xy_mm, s.v_mm_s, s.line, run, t0_s, config, end[2], end[:2]), None
    k, nxt = cut
    return _run_step(s.xy_mm[:k + 1], s.v_mm_s[:k + 1], s.line[:k + 1], run, t0_s, config,
                     end[2]), nxt


def nominal_s(block: NcBlock, max_feed_mm_s: float) -> float:
    """Length over programmed feed: a lower bound of a contour block's motion time (a NURBS by
    its control polygon, which is at least as long as the curve)."""
    if isinstance(block, NurbsBlock):
        length = block.polygon_length_mm
    elif isinstance(block, ArcBlock):
        length = block.length_mm
    else:
        assert isinstance(block, LineBlock)
        length = math.hypot(block.end[0] - block.start[0], block.end[1] - block.start[1])
    return length / max(min(block.feed_mm_s, max_feed_mm_s), 1e-9)


def _is_contour_block(block: NcBlock) -> bool:
    if isinstance(block, NurbsBlock | ArcBlock):
        return True
    return isinstance(block, LineBlock) and not block.rapid and block.start[2] == block.end[2]


class LookAhead:
    """The look-ahead of plan_program, as Klipper's LookAheadQueue: contour blocks are added,
    planned in windows (ph-lookahead) or flushed to rest, and the planned steps emitted on one
    timeline, with an in-position hold after a step that came to rest moving."""

    def __init__(self, config: MachineConfig, algorithm: Algorithm) -> None:
        self.config = config
        self.algorithm = algorithm
        self.t_s = 0.0  # time of the last sample emitted
        self.pending: list[NcBlock] = []
        self.pending_s = 0.0  # nominal motion time of the pending blocks
        self.cont: Continuation | None = None  # the cut window's rest, planned with the next
        self.repeats = Repeats()  # shared by the windows of a long run (repeats.py)
        self.settle_after: PlannedStep | None = None  # the last step, if it came to rest moving
        self.last_pos: np.ndarray | None = None  # the last reference point sent (check_steps)

    @property
    def next_t0_s(self) -> float:
        """Time of the sample after the last one emitted."""
        return self.t_s + self.config.sample_period_s

    def emit(self, step: PlannedStep | None, at_rest: bool = True,
             dwell: bool = False) -> Iterator[PlannedStep]:
        """The step, timed on from the last one (after an in-position hold if that one came to
        rest moving), and checked for jumps."""
        if step is None or not len(step.chunk):
            return
        T = self.config.sample_period_s  # noqa: N806
        if self.settle_after is not None and not dwell:
            # In-position check between moves that stop (exact stop, rapids, Z moves), as
            # Fanuc does: the next move starts once the servo has settled, so it does not
            # begin with the residual error of the last one (the dynamics module assumes rest).
            hold = _in_position_hold(self.settle_after, self.config, self.t_s)
            yield hold
            self.t_s += len(hold.chunk) * T
            step = replace(step, chunk=replace(step.chunk, t0_s=self.t_s + T))
        check_steps(step.chunk, self.last_pos, self.config)
        self.last_pos = step.chunk.pos_mm[-1]
        self.t_s = step.chunk.t0_s + (len(step.chunk) - 1) * T
        yield step
        self.settle_after = step if at_rest and not dwell else None

    def _take_pending(self) -> list[NcBlock]:
        run_blocks = list(self.pending)
        self.pending.clear()
        self.pending_s = 0.0
        return run_blocks

    def flush(self) -> Iterator[PlannedStep]:
        """Plan the pending blocks (and a cut window's rest) all the way to rest."""
        if self.pending or self.cont is not None:
            run_blocks = self._take_pending()
            step = _contour(run_blocks, self.config, self.algorithm, self.t_s, self.cont,
                            self.repeats)
            self.cont = None
            yield from self.emit(step)

    def _window(self) -> Iterator[PlannedStep]:
        run_blocks = self._take_pending()
        step, self.cont = _window(run_blocks, self.config, self.t_s, self.cont, self.repeats)
        yield from self.emit(step, at_rest=self.cont is None)

    def add(self, block: NcBlock, last_part: bool) -> Iterator[PlannedStep]:
        """Add a contour block (last_part: the last part of a programmed block); plan what a
        stop, a full window or a full run asks for."""
        self.pending.append(block)
        self.pending_s += nominal_s(block, self.config.interpolator.max_feed_mm_s)
        exact = block.path.mode != PathMode.BLEND  # type: ignore[union-attr]
        if exact and last_part:
            yield from self.flush()
        elif (len(self.pending) >= WINDOW_BLOCKS or self.pending_s >= WINDOW_NOMINAL_S) \
                and self.algorithm == Algorithm.PH_LOOKAHEAD:
            yield from self._window()
        elif len(self.pending) >= MAX_RUN_BLOCKS or self.pending_s >= MAX_RUN_NOMINAL_S:
            yield from self.flush()


def plan_program(blocks: Iterable[NcBlock], config: MachineConfig,
                 algorithm: Algorithm | str = Algorithm.PH_LOOKAHEAD) -> Iterator[PlannedStep]:
    """Group blocks into runs (rest to rest) and plan each; chunks follow each other in time.

    ph-lookahead plans long runs in look-ahead windows of WINDOW_BLOCKS new blocks (or
    WINDOW_NOMINAL_S of nominal motion), each cut mid-cruise and continued by the next (see
    _window); the other algorithms stop between windows of MAX_RUN_BLOCKS."""
    queue = LookAhead(config, Algorithm(algorithm))
    vmax = config.interpolator.max_feed_mm_s
    for block in with_synced(blocks):
        if isinstance(block, SyncMark):  # M62/M63/M67: no stop, the mark goes ahead
            yield PlannedStep(block.chunk(config, queue.next_t0_s))
            continue
        if _is_contour_block(block):
            parts = contour_parts(block, vmax) if not isinstance(block, NurbsBlock) else \
                iter(nurbs_parts(block, vmax, config.interpolator.kappa_threshold_per_mm))
            part = next(parts)
            for after in parts:  # one part ahead: the last one is known without a list
                yield from queue.add(part, False)
                part = after
            yield from queue.add(part, True)
            continue
        yield from queue.flush()
        # A long move or dwell comes in chunks, each timed on from the one before (emit may
        # put an in-position hold before the first).
        if isinstance(block, ProbeBlock):
            # A probe (G38) is a barrier: planned to rest on its own; the interpreter goes on
            # only once its result is known (controller/probe.py).
            block = block.as_line()
        moves = _straight_move(block, config, 0.0) if isinstance(block, LineBlock) else \
            helix_move(block, config, 0.0) if isinstance(block, HelixBlock) else None
        if moves is not None:  # a line that moves Z, a rapid, a probe, a helix, a G18/G19 arc
            for chunk, last in moves:
                rapid = isinstance(block, LineBlock) and block.rapid
                yield from queue.emit(PlannedStep(replace(chunk, t0_s=queue.next_t0_s),
                                                  rapid=rapid), at_rest=last)
        elif isinstance(block, DwellBlock):
            for chunk in _dwell(block, config, 0.0):
                yield from queue.emit(PlannedStep(replace(chunk, t0_s=queue.next_t0_s)),
                                      dwell=True)
        elif isinstance(block, OutputBlock):
            # Outputs are set at rest (after the in-position hold), then the spin-up wait.
            yield from queue.emit(PlannedStep(output_mark(block, config, queue.next_t0_s)),
                                  at_rest=False)
            wait = DwellBlock(block.wait_s, block.position, block.source)
            for chunk in _dwell(wait, config, 0.0):
                yield from queue.emit(PlannedStep(replace(chunk, t0_s=queue.next_t0_s)),
                                      dwell=True)
        elif isinstance(block, StopBlock) and block.kind is StopKind.PAUSE:
            # M0: settle in position, then the motion controller waits for the operator.
            yield from queue.emit(PlannedStep(_pause(block, config, queue.t_s)), dwell=True)
    yield from queue.flush()


END_MISS_MM = 1e-3  # a run's planned end this far from the programmed end is a planning fault
TRAVEL_SLACK_MM = 1e-6  # rounding only: the programs were checked against travel beforehand


STEP_SLACK = 1.01  # of the fastest feed per sample: rounding, never a jump


def check_steps(chunk: RefChunk, before_mm: np.ndarray | None, config: MachineConfig) -> None:
    """Last line of defence, as LinuxCNC's motion tests check every servo cycle: no reference
    point may be further from the one before than the fastest feed covers in one period (a
    plan that lost its way on a degenerate curve once ended with a 10 mm jump)."""
    ip = config.interpolator
    limit_mm = STEP_SLACK * max(ip.max_feed_mm_s, ip.rapid_feed_mm_s) * config.sample_period_s
    pos = chunk.pos_mm
    if not len(pos):
        return
    first = 0.0 if before_mm is None else float(np.sqrt(np.sum((pos[0] - before_mm) ** 2)))
    steps = np.sqrt(np.sum(np.diff(pos, axis=0) ** 2, axis=1))
    k = int(np.argmax(steps)) if len(steps) else 0
    jump, at = (first, 0) if not len(steps) or first >= steps[k] else (float(steps[k]), k + 1)
    if jump > limit_mm:
        raise PlanningError(f"line {int(chunk.line[at])}: the planned reference jumps "
                            f"{jump:.4f} mm in one sample (at most {limit_mm:.4f}): the "
                            "path could not be planned")


def check_travel(chunk: RefChunk, config: MachineConfig) -> None:
    """Last line of defence (soft limits, as LinuxCNC's planner also enforces them): no
    reference point may leave the machine's travel, whatever the checks before missed."""
    for i, axis in enumerate(config.axes):
        lo, hi = axis.travel_mm
        col = chunk.pos_mm[:, i]
        bad = np.flatnonzero((col < lo - TRAVEL_SLACK_MM) | (col > hi + TRAVEL_SLACK_MM))
        if bad.size:
            k = int(bad[0])
            raise PlanningError(f"line {int(chunk.line[k])}: {axis.name.upper()} reference "
                                f"{col[k]:.4f} mm outside travel [{lo:g}, {hi:g}] mm")


def generate_reference(blocks: Iterable[NcBlock], config: MachineConfig,
                       algorithm: Algorithm | str = Algorithm.PH_LOOKAHEAD) -> Iterator[RefChunk]:
    """The generator process's stream: chunks of reference points, the last one marked final;
    a chunk leaving the travel raises PlanningError instead of being sent."""
    previous: RefChunk | None = None
    for step in plan_program(blocks, config, algorithm):
        check_travel(step.chunk, config)
        if previous is not None:
            yield previous
        previous = step.chunk
    if previous is not None:
        yield replace(previous, final=True)
