"""Headless simulation of a whole program: reference points through the servo model, and figures."""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.blocks import NcBlock
from controller.config import MachineConfig
from controller.generator.dynamics.prediction import SETTLE_S, axis_servos
from controller.generator.dynamics.servo import contour_error_mm, tracking_error_mm
from controller.generator.dynamics.stops import distance_from_reference_mm
from controller.generator.loop import RunPlan, RunStatus
from controller.generator.plan import Algorithm, PlannedStep, plan_program


@dataclass(frozen=True, eq=False)
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


def _exact_where_known(phi: np.ndarray, steps: list[PlannedStep]) -> np.ndarray:
    """Eq. 28 wants the path tangent: the generator's exact one where it has it (contour runs),
    central differences of the reference elsewhere (straight moves, holds)."""
    k = 0
    for step in steps:
        n = len(step.chunk)
        if step.phi_rad is not None:
            phi[k:k + n] = step.phi_rad
        k += n
    phi[k:] = phi[k - 1] if k else phi[k:]
    return phi


def simulate(blocks: Iterable[NcBlock], config: MachineConfig,
             algorithm: Algorithm | str) -> Trajectory:
    """Plan the program, then run the reference through both axis models from X0 Y0 at rest."""
    cpu0 = time.process_time()
    steps = list(plan_program(blocks, config, algorithm))
    cpu = time.process_time() - cpu0
    if not steps:
        empty = np.zeros((0, len(config.axis_names)))
        z = np.zeros(0)
        return Trajectory(z, empty, empty, z, z.astype(np.int32), z, z, z, z.astype(bool), z,
                          (), cpu)
    ref = np.vstack([s.chunk.pos_mm for s in steps])
    T = config.sample_period_s  # noqa: N806
    settle = int(round(SETTLE_S / T))
    start = np.zeros((1, ref.shape[1]))
    pos = np.vstack([start, ref, np.repeat(ref[-1:], settle, axis=0)])
    v = np.diff(pos, axis=0) / T
    servos = axis_servos(config)
    ex = tracking_error_mm(servos[0], v[:, 0])
    ey = tracking_error_mm(servos[1], v[:, 1])
    phi = _exact_where_known(tangent_angles(pos[1:, :2]), steps)
    n = len(ref)
    act = ref.copy()
    act[:, 0] -= ex[:n]
    act[:, 1] -= ey[:n]
    runs = tuple(s.run for s in steps if s.run is not None)
    rapid = np.concatenate([np.full(len(s.chunk), s.rapid) for s in steps])
    contouring = ~np.r_[rapid, np.full(settle, rapid[-1])]
    held = pos[1:, :2]
    true = distance_from_reference_mm(held, held - np.column_stack([ex, ey]))
    return Trajectory(np.arange(1, n + 1) * T, ref, act,
                      np.concatenate([s.chunk.feed_mm_s for s in steps]),
                      np.concatenate([s.chunk.line for s in steps]), ex, ey,
                      contour_error_mm(ex, ey, phi), contouring, true, runs, cpu)


def _stats_um(e_mm: np.ndarray) -> dict[str, float]:
    a = np.abs(e_mm) * 1000.0
    if a.size == 0:
        return {"max": 0.0, "rms": 0.0, "mean": 0.0}
    return {"max": float(a.max()), "rms": float(np.sqrt(np.mean(a * a))), "mean": float(a.mean())}


def _ph_fit(runs: tuple[RunPlan, ...]) -> dict[str, float]:
    infos = [c for r in runs for c in r.corners if c.ph_count]
    if not infos:
        return {"max": 0.0, "rms": 0.0}
    return {"max": max(c.fit_max_mm for c in infos) * 1000.0,
            "rms": float(np.sqrt(np.mean([c.fit_rms_mm**2 for c in infos]))) * 1000.0}


def _true_um(traj: Trajectory, T: float) -> dict[str, Any]:  # noqa: N803
    """The true contour error's max and RMS over contouring samples, and where the max is."""
    e = np.where(traj.contouring, traj.true_mm, 0.0)
    if e.size == 0:
        return {"max": 0.0, "rms": 0.0, "at": None}
    k = int(np.argmax(e))
    n = len(traj.t_s)
    row = traj.ref_mm[min(k, n - 1)]
    at = {"t_s": round((k + 1) * T, 6), "line": int(traj.line[min(k, n - 1)]),
          "x_mm": round(float(row[0] - traj.ex_mm[k]), 6),
          "y_mm": round(float(row[1] - traj.ey_mm[k]), 6), "after_end": k >= n}
    used = traj.true_mm[traj.contouring] * 1000.0  # none when the program only has rapids
    rms = float(np.sqrt(np.mean(used * used))) if used.size else 0.0
    return {"max": float(e[k] * 1000.0), "rms": rms, "at": at}


def report(traj: Trajectory, program: str, algorithm: str, config: MachineConfig) -> dict:
    """The JSON object of `cncctl simulate --json`."""
    T = config.sample_period_s  # noqa: N806
    start = np.zeros((1, traj.ref_mm.shape[1]))
    steps = np.linalg.norm(np.diff(np.vstack([start, traj.ref_mm]), axis=0), axis=1) / T
    accel = np.diff(steps) / T if steps.size > 1 else np.zeros(1)
    x, y = _stats_um(traj.ex_mm), _stats_um(traj.ey_mm)
    true = _true_um(traj, T)
    return {
        "program": program,
        "algorithm": algorithm,
        "motion_time_s": float(len(traj.t_s) * T),
        "samples": int(len(traj.t_s)),
        "sample_period_s": T,
        "tracking_error_um": {"x": {"max": x["max"], "rms": x["rms"]},
                              "y": {"max": y["max"], "rms": y["rms"]}},
        "contour_error_um": _stats_um(traj.contour_mm[traj.contouring]),
        "contour_error_true_um": true,
        "max_feed_mm_s": float(steps.max()) if steps.size else 0.0,
        "max_tangential_accel_mm_s2": float(np.abs(accel).max()) if accel.size else 0.0,
        "sharp_corners": sum(len(r.corners) for r in traj.runs),
        "ph_segments": sum(len(r.geometry.ph_pieces) for r in traj.runs),
        "ph_fit_error_um": _ph_fit(traj.runs),
        "dynamics_rounds": max((r.dynamics_rounds for r in traj.runs), default=0),
        # The limit is on the tool's distance from the path (eq. 28 stays, for Table IV).
        "contour_limit_met": all(r.status == RunStatus.OK for r in traj.runs)
        and true["max"] <= config.interpolator.contour_error_limit_mm * 1000.0 + 1e-9,
        "planning_cpu_s": traj.planning_cpu_s,
    }


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
