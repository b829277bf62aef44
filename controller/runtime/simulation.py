"""Headless simulation of a whole program: reference points through the servo model, and figures."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from controller.blocks import NcBlock
from controller.config import MachineConfig
from controller.generator.plan import Algorithm, PlannedStep, plan_program
from controller.generator.replan import RunPlan
from controller.runtime.simulate_figures import Figures
from controller.runtime.simulate_stream import SampleBlock, ServoStream


@dataclass(frozen=True, eq=False, repr=False)
class Trajectory:
    """The whole program's reference points and the servo model's answer (virtual time)."""

    t_s: np.ndarray
    ref_mm: np.ndarray  # (N, n_axes)
    act_mm: np.ndarray  # (N, n_axes) = ref - tracking error
    feed_mm_s: np.ndarray
    line: np.ndarray
    ex_mm: np.ndarray  # including SETTLE_S after the end
    ey_mm: np.ndarray
    contour_mm: np.ndarray
    contouring: np.ndarray  # per entry of contour_mm: False on rapids (not a contour)
    true_mm: np.ndarray  # distance of the modelled tool from the path (settling included)
    runs: tuple[RunPlan, ...]
    planning_cpu_s: float


def tangent_angles(xy: np.ndarray) -> np.ndarray:
    """Path tangent angle at each sample by central differences (held where the path stops)."""
    padded = np.vstack([xy[:1], xy, xy[-1:]])
    d = padded[2:] - padded[:-2]
    moving = np.hypot(d[:, 0], d[:, 1]) > 1e-9
    phi = np.arctan2(d[:, 1], d[:, 0])
    idx = np.where(moving, np.arange(len(phi)), 0)
    np.maximum.accumulate(idx, out=idx)
    return phi[idx]


SampleSink = Callable[[SampleBlock], None]


def _timed(steps: Iterator[PlannedStep], clock: list[float]) -> Iterator[PlannedStep]:
    """The steps, the CPU time spent producing them added to clock[0]."""
    while True:
        cpu0 = time.process_time()
        step = next(steps, None)
        clock[0] += time.process_time() - cpu0
        if step is None:
            return
        yield step


def simulate_stream(blocks: Iterable[NcBlock], config: MachineConfig, algorithm: Algorithm | str,
                    sinks: list[SampleSink], on_run: Callable[[RunPlan], None] | None = None,
                    ) -> float:
    """Plan the program and run it through both axis models from X0 Y0 at rest, handing every
    finished block of samples to each sink as it comes (memory bounded whatever the length).
    on_run sees each contour run's plan. Returns the CPU time spent planning."""
    clock = [0.0]
    stream = ServoStream(config)
    for step in _timed(iter(plan_program(blocks, config, algorithm)), clock):
        if step.run is not None and on_run is not None:
            on_run(step.run)
        c = step.chunk
        if not len(c):  # a mark of outputs set with the next move (M62): no samples
            continue
        for b in stream.push(c.pos_mm, c.feed_mm_s, c.line, step.rapid, step.phi_rad):
            for sink in sinks:
                sink(b)
    for b in stream.finish():
        for sink in sinks:
            sink(b)
    return clock[0]


class _Collector:
    """Every sample block kept, for the whole-array Trajectory."""

    def __init__(self) -> None:
        self.blocks: list[SampleBlock] = []

    def add(self, b: SampleBlock) -> None:
        self.blocks.append(b)

    def trajectory(self, config: MachineConfig, runs: list[RunPlan], cpu_s: float) -> Trajectory:
        bs = self.blocks
        if not bs:
            empty = np.zeros((0, len(config.axis_names)))
            z = np.zeros(0)
            return Trajectory(z, empty, empty, z, z.astype(np.int32), z, z, z, z.astype(bool), z,
                              tuple(runs), cpu_s)

        def cat(name: str, ref_only: bool = False) -> np.ndarray:
            return np.concatenate([getattr(b, name)[:b.n_ref] if ref_only else getattr(b, name)
                                   for b in bs])
        ref = cat("ref_mm", True)
        n = len(ref)
        ex, ey = cat("ex_mm"), cat("ey_mm")
        act = ref.copy()
        act[:, 0] -= ex[:n]
        act[:, 1] -= ey[:n]
        return Trajectory(np.arange(1, n + 1) * config.sample_period_s, ref, act,
                          cat("feed_mm_s", True), cat("line", True), ex, ey, cat("contour_mm"),
                          cat("contouring"), cat("true_mm"), tuple(runs), cpu_s)


def simulate(blocks: Iterable[NcBlock], config: MachineConfig,
             algorithm: Algorithm | str) -> Trajectory:
    """The whole program's trajectory as arrays (simulate_stream, every sample kept: for tests
    and short programs; `cncctl simulate` streams)."""
    collect = _Collector()
    runs: list[RunPlan] = []
    cpu = simulate_stream(blocks, config, algorithm, [collect.add], runs.append)
    return collect.trajectory(config, runs, cpu)


def report(traj: Trajectory, program: str, algorithm: str, config: MachineConfig) -> dict:
    """The JSON object of `cncctl simulate --json`, from a whole trajectory."""
    n = len(traj.t_s)
    figures = Figures(traj.ref_mm.shape[1], config.sample_period_s)
    for run in traj.runs:
        figures.runs.add(run)
    if len(traj.ex_mm):
        ref = np.vstack([traj.ref_mm, np.repeat(traj.ref_mm[-1:], len(traj.ex_mm) - n, axis=0)])
        line = np.r_[traj.line, np.full(len(traj.ex_mm) - n, traj.line[-1])]
        figures.add(SampleBlock(0, n, ref, traj.feed_mm_s, line, traj.ex_mm, traj.ey_mm,
                                traj.contour_mm, traj.contouring, traj.true_mm))
    return figures.report(program, algorithm, limit_um(config), traj.planning_cpu_s)


def limit_um(config: MachineConfig) -> float:
    return config.interpolator.contour_error_limit_mm * 1000.0


def table_iv_failures(results: dict[str, dict], limit_um: float) -> list[str]:
    """Section 5.1's qualitative result over report() dicts keyed by algorithm: both formula
    feeds exceed the contour limit, both look-ahead algorithms keep it, and ph-lookahead is the
    faster of those two. The conditions that do not hold (empty: the result holds)."""
    err = {a: r["contour_error_um"]["max"] for a, r in results.items()}
    checks = {
        "adaptive exceeds the limit": err["adaptive"] > limit_um,
        "curvature exceeds the limit": err["curvature"] > limit_um,
        "nurbs-lookahead keeps the limit": err["nurbs-lookahead"] <= limit_um,
        "ph-lookahead keeps the limit": err["ph-lookahead"] <= limit_um,
        "ph-lookahead is faster than nurbs-lookahead":
            results["ph-lookahead"]["motion_time_s"] < results["nurbs-lookahead"]["motion_time_s"],
    }
    return [name for name, ok in checks.items() if not ok]
