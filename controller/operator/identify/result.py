"""The outcome of `cncctl identify` once the axes have moved: each record fitted, the report
lines, and what a client needs to write the config (embedded and in cncd alike)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from controller.config import MachineConfig, ServoParams
from controller.operator.identify.loop import AxisRecord
from controller.operator.identify.report import (
    NAMES,
    contour_meaning,
    fit_lines,
    meaning_lines,
    normalised,
    parameter_lines,
)
from controller.servo.fit import AxisFit, fit_axis

MIN_FIT_PCT = 80.0  # held-out fit below this: the loop is not explained, nothing written


@dataclass
class Identified:
    """The report's lines; the loops identified; the axes refused (then nothing is written);
    problem: a record that could not be fitted at all."""

    lines: list[str] = field(default_factory=list)
    fits: dict[str, AxisFit] = field(default_factory=dict)
    refused: list[str] = field(default_factory=list)
    problem: str | None = None
    meaning: dict[str, Any] | None = None

    @property
    def identified(self) -> dict[str, ServoParams]:
        return {n: f.params for n, f in self.fits.items()}

    def as_dict(self) -> dict[str, Any]:
        """For the wire: every figure the report shows, the parameters with a4 = 1."""
        return {
            "report": self.lines, "refused": self.refused, "problem": self.problem,
            "meaning": self.meaning,
            "fits": {n: {"fit_pct": f.fit_pct, "fit_pct_in_force": f.fit_pct_in_force,
                         "rms_um": f.rms_um, "problem": f.problem,
                         "params": {k: getattr(normalised(f.params), k) for k in NAMES}}
                     for n, f in self.fits.items()},
        }


def params_from_wire(fits: dict[str, Any]) -> dict[str, ServoParams]:
    """The identified loops as the daemon sent them (as_dict's `fits`)."""
    return {name: ServoParams(**{k: float(f["params"][k]) for k in NAMES})
            for name, f in fits.items()}


def fit_records(config: MachineConfig, records: list[AxisRecord]) -> Identified:
    out = Identified()
    for rec in records:
        try:
            out.fits[rec.axis] = _fit(config, rec)
        except ValueError as exc:
            out.problem = f"{rec.axis.upper()}: {exc}"
            return out
    for name, fit in out.fits.items():
        out.lines += fit_lines(name, fit, MIN_FIT_PCT)
    for name, fit in out.fits.items():
        out.lines += parameter_lines(name, config.axis(name).servo, fit.params)
    out.refused = [n for n, f in out.fits.items()
                   if f.problem is not None or f.fit_pct < MIN_FIT_PCT]
    if not out.refused:
        meaning = contour_meaning(config, out.identified)
        if meaning is not None:
            out.lines += meaning_lines(meaning)
            out.meaning = asdict(meaning)
    return out


def _fit(config: MachineConfig, rec: AxisRecord) -> AxisFit:
    axis = config.axis(rec.axis)
    return fit_axis(rec.commanded_counts * axis.pulse_mm, rec.encoder_counts * axis.pulse_mm,
                    axis.servo, config.sample_period_s, rec.rest_samples, rec.sample_index)
