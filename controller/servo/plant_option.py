"""Drive options giving the simulated drives a plant of their own: plant_x=a0,a1,...,b2 per axis.

A simulated table runs each axis through a servo loop of the eq. 27 form (docs/algorithms.md,
The servo model (eq. 27)). By default that loop is the config's model, so the planner knows the
machine exactly; `plant_<axis>` replaces it with any other stable loop, so that tests and benches
can run a machine the controller does not know. The percentage options `plant_pole_pct` and
`plant_gain_pct` (see mismatched) apply on top of that plant, or of the config's model when no
plant is given. A bad value is a PlantOptionError whose message starts with the option's name.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import astuple, fields, replace
from typing import Any

from controller.config import MachineConfig, ServoParams
from controller.servo.model import mismatched
from controller.servo_poles import pole_problem

COEFFICIENTS = tuple(f.name for f in fields(ServoParams))  # a0, a1, a2, a3, a4, b0, b1, b2
AXIS_PLANT_OPTIONS = frozenset(f"plant_{name}" for name in ("x", "y", "z"))
PCT_OPTIONS = {"plant_pole_pct": (-50.0, 100.0), "plant_gain_pct": (-50.0, 100.0)}
PLANT_OPTIONS = AXIS_PLANT_OPTIONS | frozenset(PCT_OPTIONS)
MAX_COEFFICIENT = 1e30  # as a config's servo key: beyond it the poles cannot be computed
STATIC_GAIN_RANGE = (0.5, 2.0)  # b0 / a0, as a config's servo key: a position loop tracks


class PlantOptionError(ValueError):
    """A plant option that no simulated drive can run: the message names the option."""


def plant_text(params: ServoParams) -> str:
    """The option value of a plant, `a0,a1,a2,a3,a4,b0,b1,b2`; parse_plant reads it back exactly."""
    return ",".join(repr(float(v)) for v in astuple(params))


def parse_plant(value: Any, sample_period_s: float, key: str = "plant_x") -> ServoParams:
    """Eight numbers a0,a1,a2,a3,a4,b0,b1,b2 (text with commas, or a list from YAML) of a
    loop that is stable, damped and sampled fast enough at sample_period_s (servo_poles)."""
    numbers = _numbers(value, key)
    params = ServoParams(**dict(zip(COEFFICIENTS, numbers, strict=True)))
    if params.a4 <= 0.0 or params.a0 <= 0.0:
        raise PlantOptionError(f"{key}: a4 and a0 must be positive, got a4 = {params.a4:g}, "
                               f"a0 = {params.a0:g}")
    ratio = params.b0 / params.a0
    if not STATIC_GAIN_RANGE[0] <= ratio <= STATIC_GAIN_RANGE[1]:
        raise PlantOptionError(f"{key}: b0 / a0 = {ratio:.3g}: a position loop's static gain "
                               "must be near 1 (b0 = a0)")
    problem = pole_problem((params.a4, params.a3, params.a2, params.a1, params.a0),
                           sample_period_s)
    if problem is not None:
        raise PlantOptionError(f"{key}: {problem}")
    return params


def _numbers(value: Any, key: str) -> list[float]:
    """The eight coefficients of an option value, each a finite number within range."""
    words: Sequence[Any]
    if isinstance(value, str):
        words = [w.strip() for w in value.split(",")]
    elif isinstance(value, list | tuple):
        words = value
    else:
        words = [value]
    if len(words) != len(COEFFICIENTS):
        raise PlantOptionError(f"{key}: expected eight numbers a0,a1,a2,a3,a4,b0,b1,b2 "
                               f"(eq. 27), got {len(words)} in {_shown(value)}")
    numbers = []
    for name, word in zip(COEFFICIENTS, words, strict=True):
        try:
            if isinstance(word, bool):
                raise TypeError
            number = float(word)
        except (TypeError, ValueError, OverflowError):
            raise PlantOptionError(f"{key}: {name} = {_shown(word)} is not a number") from None
        if not math.isfinite(number) or abs(number) > MAX_COEFFICIENT:
            raise PlantOptionError(f"{key}: {name} = {_shown(word)} is not a finite number "
                                   f"within +-{MAX_COEFFICIENT:g}")
        numbers.append(number)
    return numbers


def _shown(value: Any) -> str:
    """A value as the operator typed it, cut short (an option can be any length)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _pct(options: Mapping[str, Any], key: str) -> float:
    value = options.get(key, 0.0)
    lo, hi = PCT_OPTIONS[key]
    try:
        if isinstance(value, bool):
            raise TypeError
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise PlantOptionError(f"{key}: {value!r} is not a number") from None
    if not lo <= number <= hi:  # NaN fails here too
        raise PlantOptionError(f"{key}: {value!r} is not in [{lo:g}, {hi:g}]")
    return number


def plant_config(config: MachineConfig, options: Mapping[str, Any]) -> MachineConfig:
    """The machine the simulated drive runs: each axis's servo replaced by its plant_<axis>
    option when given, then every axis mismatched by plant_pole_pct and plant_gain_pct (within
    -50..+100 % the config's model stays a stable, damped loop). Other options are ignored."""
    pole_pct, gain_pct = _pct(options, "plant_pole_pct"), _pct(options, "plant_gain_pct")
    period_s = config.sample_period_s
    given = sorted(k for k in options if k in AXIS_PLANT_OPTIONS)
    for key in given:
        if not config.has_axis(key.removeprefix("plant_")):
            raise PlantOptionError(f"{key}: the machine has no {key[-1].upper()} axis (axes "
                                   f"{', '.join(config.axis_names)})")
    axes = []
    for axis in config.axes:
        key = f"plant_{axis.name}"
        if key not in options:
            axes.append(replace(axis, servo=mismatched(axis.servo, pole_pct, gain_pct)))
            continue
        plant = mismatched(parse_plant(options[key], period_s, key), pole_pct, gain_pct)
        # Faster poles (plant_pole_pct > 0) may pass the Nyquist rate the given plant was under.
        problem = pole_problem((plant.a4, plant.a3, plant.a2, plant.a1, plant.a0), period_s)
        if problem is not None:
            raise PlantOptionError(f"{key}: with plant_pole_pct = {pole_pct:g}: {problem}")
        axes.append(replace(axis, servo=plant))
    return replace(config, axes=tuple(axes))
