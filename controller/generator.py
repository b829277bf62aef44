"""The reference-point generator: NC blocks in, one reference point per sample period out."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from controller.baselines import FORMULA_FEEDS, plan_formula_run
from controller.blocks import (
    ArcBlock,
    DwellBlock,
    LineBlock,
    NcBlock,
    NurbsBlock,
    PathMode,
)
from controller.config import MachineConfig
from controller.feed_planner import plan_feed
from controller.gen_geometry import BlockCurve, block_curve
from controller.gen_run import NURBS_LOOKAHEAD, PH_LOOKAHEAD, RunPlan, plan_contour_run
from controller.refpoints import RefChunk

MAX_RUN_BLOCKS = 500  # look-ahead window: a longer contour is planned in pieces, stopping between


class Algorithm(StrEnum):
    ADAPTIVE = "adaptive"  # Yeh & Hsu 2002: feed = min(Vmax, V_af)
    CURVATURE = "curvature"  # Zhiming et al. 2002: feed = V_cf
    NURBS_LOOKAHEAD = "nurbs-lookahead"  # Tsai et al. 2008
    PH_LOOKAHEAD = "ph-lookahead"  # this controller (the paper's algorithm)


@dataclass(frozen=True, eq=False)
class PlannedStep:
    """One chunk of reference points and, for contour runs, how it was planned."""

    chunk: RefChunk
    run: RunPlan | None = None


def _pos_row(config: MachineConfig, xy: np.ndarray, z_mm: float) -> np.ndarray:
    if config.has_axis("z"):
        return np.column_stack([xy, np.full(len(xy), z_mm)])
    return xy


def _straight_move(block: LineBlock, config: MachineConfig, t0_s: float) -> RefChunk | None:
    """A line that moves Z, or a rapid: its own quintic feed profile from rest to rest."""
    start, end = np.array(block.start), np.array(block.end)
    if not config.has_axis("z"):
        start, end = start[:2], end[:2]
    length = float(np.linalg.norm(end - start))
    if length < 1e-9:
        return None
    cap = config.interpolator.rapid_feed_mm_s if block.rapid else min(
        block.feed_mm_s, config.interpolator.max_feed_mm_s)
    plan = plan_feed(np.array([0.0, length]), np.array([cap, cap]),
                     config.interpolator.max_accel_mm_s2)
    T = config.sample_period_s  # noqa: N806
    k = max(int(np.ceil(plan.profile.duration_s / T - 1e-9)), 1)
    s, v, _ = plan.profile.evaluate(np.minimum(np.arange(1, k + 1) * T, plan.profile.duration_s))
    pos = start + (s / length)[:, None] * (end - start)
    pos[-1] = end
    line = np.full(k, block.source.first_line, np.int32)
    return RefChunk(t0_s + T, pos, v, line)


def _dwell(block: DwellBlock, config: MachineConfig, t0_s: float) -> RefChunk | None:
    T = config.sample_period_s  # noqa: N806
    k = int(round(block.seconds / T))
    if k <= 0:
        return None
    pos = np.array(block.position)[: len(config.axis_names)]
    rows = np.repeat(pos[None, :], k, axis=0)
    return RefChunk(t0_s + T, rows, np.zeros(k), np.full(k, block.source.first_line, np.int32))


def plan_run(curves: list[BlockCurve], start_xy: np.ndarray, config: MachineConfig,
             algorithm: Algorithm) -> tuple[RunPlan | None, np.ndarray, np.ndarray, np.ndarray]:
    """Plan one XY contour run with the chosen algorithm: (report, xy, feed, line)."""
    if algorithm in FORMULA_FEEDS:
        s = plan_formula_run(curves, config, algorithm.value)
        return None, s.xy_mm, s.v_mm_s, s.line
    settings = PH_LOOKAHEAD if algorithm == Algorithm.PH_LOOKAHEAD else NURBS_LOOKAHEAD
    run = plan_contour_run(curves, start_xy, config, settings)
    return run, run.samples.xy_mm, run.samples.v_mm_s, run.samples.line


def _contour(blocks: list[NcBlock], config: MachineConfig, algorithm: Algorithm,
             t0_s: float) -> PlannedStep | None:
    ip = config.interpolator
    curves = [c for b in blocks
              if (c := block_curve(b, ip.max_feed_mm_s, ip.contour_error_limit_mm)) is not None]
    if not curves:
        return None
    start = np.array(blocks[0].start[:2])
    run, xy, v, line = plan_run(curves, start, config, algorithm)
    xy[-1] = blocks[-1].end[:2]  # the programmed end point exactly, not a curve evaluation
    pos = _pos_row(config, xy, blocks[0].start[2])
    return PlannedStep(RefChunk(t0_s + config.sample_period_s, pos, v, line), run)


def _is_contour_block(block: NcBlock) -> bool:
    if isinstance(block, NurbsBlock | ArcBlock):
        return True
    return isinstance(block, LineBlock) and not block.rapid and block.start[2] == block.end[2]


def plan_program(blocks: Iterable[NcBlock], config: MachineConfig,
                 algorithm: Algorithm | str = Algorithm.PH_LOOKAHEAD) -> Iterator[PlannedStep]:
    """Group blocks into runs (rest to rest) and plan each; chunks follow each other in time."""
    algorithm = Algorithm(algorithm)
    T = config.sample_period_s  # noqa: N806
    t_s = 0.0
    pending: list[NcBlock] = []

    def emit(step: PlannedStep | None) -> Iterator[PlannedStep]:
        nonlocal t_s
        if step is not None and len(step.chunk):
            t_s = step.chunk.t0_s + (len(step.chunk) - 1) * T
            yield step

    def flush() -> Iterator[PlannedStep]:
        if pending:
            run_blocks = list(pending)
            pending.clear()
            yield from emit(_contour(run_blocks, config, algorithm, t_s))

    for block in blocks:
        if _is_contour_block(block):
            pending.append(block)  # type: ignore[arg-type]
            exact = block.path.mode != PathMode.BLEND  # type: ignore[union-attr]
            if exact or len(pending) >= MAX_RUN_BLOCKS:
                yield from flush()
            continue
        yield from flush()
        if isinstance(block, LineBlock):
            chunk = _straight_move(block, config, t_s)
            yield from emit(PlannedStep(chunk) if chunk is not None else None)
        elif isinstance(block, DwellBlock):
            chunk = _dwell(block, config, t_s)
            yield from emit(PlannedStep(chunk) if chunk is not None else None)
    yield from flush()


def generate_reference(blocks: Iterable[NcBlock], config: MachineConfig,
                       algorithm: Algorithm | str = Algorithm.PH_LOOKAHEAD) -> Iterator[RefChunk]:
    """The generator process's stream: chunks of reference points, the last one marked final."""
    previous: RefChunk | None = None
    for step in plan_program(blocks, config, algorithm):
        if previous is not None:
            yield previous
        previous = step.chunk
    if previous is not None:
        yield RefChunk(previous.t0_s, previous.pos_mm, previous.feed_mm_s, previous.line, True)
