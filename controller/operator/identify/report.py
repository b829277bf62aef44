"""What `cncctl identify` prints and writes: the fit's quality, the parameters side by side,
their meaning in contour error on a reference curve, and the config with the identified loops."""

from __future__ import annotations

import datetime
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from controller.config import MachineConfig, ServoParams, load_config
from controller.errors import CncError
from controller.generator.plan import Algorithm
from controller.interpreter.program import read_program
from controller.runtime.simulation import simulate, tangent_angles
from controller.servo.fit import AxisFit, simulate_error_mm
from controller.servo.precompensation import Precompensator

NAMES = ("a0", "a1", "a2", "a3", "a4", "b0", "b1", "b2")
REFERENCE_PROGRAM = Path(__file__).resolve().parents[3] / "nc_programs" / "naca2415.nc"


def normalised(p: ServoParams) -> ServoParams:
    """The same loop with a4 = 1 (how a config states it, and how a fit returns it)."""
    return ServoParams(*(getattr(p, n) / p.a4 for n in NAMES))


def parameter_lines(name: str, in_force: ServoParams, found: ServoParams) -> list[str]:
    """The model in force and the identified one side by side, a4 = 1 for both."""
    a, b = normalised(in_force), normalised(found)
    lines = [f"{name.upper()}  {'':3}{'in force':>14} {'identified':>14} {'change':>9}"]
    for n in NAMES:
        x, y = getattr(a, n), getattr(b, n)
        lines.append(f"    {n:3}{x:14.6g} {y:14.6g} {100.0 * (y - x) / x:+8.2f}%")
    c1 = [(p.a1 - p.b1) / p.a0 for p in (a, b)]
    c2 = [(p.a2 - p.b2) / p.a0 - p.a1 * (p.a1 - p.b1) / p.a0**2 for p in (a, b)]
    lines.append(f"    velocity lag c1 {c1[0]:.4e} -> {c1[1]:.4e} s, "
                 f"acceleration gain c2 {c2[0]:.4e} -> {c2[1]:.4e} s^2")
    return lines


def fit_lines(name: str, fit: AxisFit, min_fit_pct: float) -> list[str]:
    verdict = "usable" if fit.problem is None and fit.fit_pct >= min_fit_pct else "REFUSED"
    text = (f"{name.upper()}  fit on held-out data: {fit.fit_pct:.1f} % identified, "
            f"{fit.fit_pct_in_force:.1f} % the model in force (residual {fit.rms_um:.3f} um "
            f"RMS, {fit.iterations} iterations): {verdict}")
    out = [text]
    if fit.problem is not None:
        out.append(f"    the identified loop is unusable: {fit.problem}")
    elif fit.fit_pct < min_fit_pct:
        out.append(f"    fits worse than {min_fit_pct:.0f} %: the loop is not the eq. 27 model "
                   "here (backlash, friction, a resonance?), or the record is too noisy")
    return out


@dataclass(frozen=True)
class Meaning:
    """The reference curve planned with the model in force, run through each loop."""

    program: str
    limit_um: float
    in_force_um: float  # contour error max, through the model in force (what was planned for)
    identified_um: float  # the same plan through the identified loops


def contour_meaning(config: MachineConfig, identified: dict[str, ServoParams],
                    program: Path = REFERENCE_PROGRAM) -> Meaning | None:
    """Plan `program` with the model in force, then follow what the motion loop would send
    (the wanted path through the pre-compensation in force) with each set of loops; eq. 28's
    contour error max over the contouring samples. None without an X-Y machine or program."""
    if not (config.has_axis("x") and config.has_axis("y")) or not program.is_file():
        return None
    traj = simulate(read_program(str(program), config), config, Algorithm.PH_LOOKAHEAD)
    n_ref, n_all = len(traj.ref_mm), len(traj.ex_mm)
    wanted = np.vstack([traj.ref_mm, np.repeat(traj.ref_mm[-1:], n_all - n_ref, axis=0)])
    start = np.zeros(wanted.shape[1])  # simulate starts at rest at the origin
    cmd = wanted
    if config.interpolator.servo_precompensation:
        comp = Precompensator([a.servo if a.name in ("x", "y") else None for a in config.axes],
                              config.sample_period_s, start)
        cmd = comp.push(wanted)
    phi = tangent_angles(wanted[:, :2])
    v = np.diff(np.vstack([start[None, :], cmd]), axis=0) / config.sample_period_s

    def contour_max_um(servos: dict[str, ServoParams]) -> float:
        dev = []
        for i, name in enumerate(("x", "y")):
            e = simulate_error_mm(servos[name], v[:, i], config.sample_period_s)
            dev.append(wanted[:, i] - (cmd[:, i] - e))  # the wanted path less the tool
        eps = -dev[0] * np.sin(phi) + dev[1] * np.cos(phi)
        return 1000.0 * float(np.abs(eps[traj.contouring]).max())

    in_force = {n: config.axis(n).servo for n in ("x", "y")}
    return Meaning(program.name, config.interpolator.contour_error_limit_mm * 1000.0,
                   contour_max_um(in_force), contour_max_um(in_force | identified))


def meaning_lines(m: Meaning) -> list[str]:
    worse = m.identified_um > m.limit_um
    return [f"{m.program} planned with the model in force: contour error max "
            f"{m.in_force_um:.2f} um through the model in force, {m.identified_um:.2f} um "
            f"through the identified loops (limit {m.limit_um:.0f} um)"
            + (": the machine would break the limit; plan with the identified model"
               if worse else "")]


def write_config(config: MachineConfig, identified: dict[str, ServoParams], path: str) -> None:
    """The config file in force with the identified `servo` blocks (see write_config_text)."""
    with open(config.path, encoding="utf-8") as fh:
        source = fh.read()
    write_config_text(source, config.name, config.path, identified, path)


def write_config_text(source: str, name: str, source_path: str,
                      identified: dict[str, ServoParams], path: str) -> None:
    """`source`, a config file's text, with the identified `servo` blocks, written to `path`
    and loaded back to check it (removed again if it does not load). Drive options given on
    a command line are not written: they belong to one invocation."""
    data = yaml.safe_load(source)
    for axis, p in identified.items():
        data["axes"][axis]["servo"] = {n: float(f"{getattr(normalised(p), n):.7g}")
                                       for n in NAMES}
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    head = (f"# {name} with the servo loops of {', '.join(n.upper() for n in identified)}"
            f" identified by `cncctl identify` on {stamp}\n# from {source_path}\n")
    part = path + ".part"
    with open(part, "w", encoding="utf-8") as fh:
        fh.write(head + yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
    os.replace(part, path)
    try:
        load_config(path)
    except CncError:
        os.unlink(path)
        raise


def with_servos(config: MachineConfig, identified: dict[str, ServoParams]) -> MachineConfig:
    axes = tuple(replace(a, servo=identified.get(a.name, a.servo)) for a in config.axes)
    return replace(config, axes=axes)
