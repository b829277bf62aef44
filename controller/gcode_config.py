"""The `gcode` section of a machine config: subroutine folders, start state, Centroid's rules."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from controller.errors import ConfigError

POWER_UP_MOTIONS = ("none", "G0")
MAIN_PROGRAM_M99 = ("restart", "end")
M25_RULES = ("refuse", "z_home")


@dataclass(frozen=True, slots=True)
class GcodeConfig:
    """subroutine_path: folders (absolute) searched, after the program's own folder, for the
    file `name.ngc` of an `o<name> call` whose subroutine the program does not hold (LinuxCNC's
    [RS274NGC]SUBROUTINE_PATH).

    default_feed_mm_min: the feed of a G1/G2/G3 before the program's first F (Klipper's and
    Marlin's rule); None refuses such a move, as LinuxCNC and grbl do.

    power_up_motion: the motion mode an axis word follows before the program's first motion
    code: "none" refuses it (LinuxCNC), "G0" moves at rapid (grbl's power-up state).

    main_program_m99: "restart" starts the main program again at an M99 (LinuxCNC's task,
    Fanuc), "end" ends the job there like M2 (Centroid).

    m25: "refuse" refuses M25 (LinuxCNC does not know it), "z_home" reads it as Centroid's
    "move Z to its home position": a rapid of Z alone, as G53 G0 Z<home>."""

    subroutine_path: tuple[str, ...] = ()
    default_feed_mm_min: float | None = None
    power_up_motion: str = "none"
    main_program_m99: str = "restart"
    m25: str = "refuse"


def read_gcode_section(sec: Any) -> GcodeConfig:
    """The section (a yaml_strict Section); folders relative to the config's folder must exist."""
    folders = _subroutine_path(sec)
    feed = _default_feed(sec)
    motion = sec.str("power_up_motion", "none", choices=POWER_UP_MOTIONS)
    m99 = sec.str("main_program_m99", "restart", choices=MAIN_PROGRAM_M99)
    m25 = sec.str("m25", "refuse", choices=M25_RULES)
    sec.finish()
    return GcodeConfig(folders, feed, motion, m99, m25)


def _subroutine_path(sec: Any) -> tuple[str, ...]:
    raw = sec._raw("subroutine_path", [])
    key = sec._key("subroutine_path")
    if not isinstance(raw, list) or not all(isinstance(d, str) and d for d in raw):
        raise ConfigError(sec.path, key, "must be a list of folder names")
    base = os.path.dirname(os.path.abspath(sec.path))
    folders = tuple(os.path.join(base, os.path.expanduser(d)) for d in raw)
    for name, folder in zip(raw, folders, strict=True):
        if not os.path.isdir(folder):
            raise ConfigError(sec.path, key, f"{name}: no such folder")
    return folders


def _default_feed(sec: Any) -> float | None:
    if sec._raw("default_feed_mm_min", None) is None:
        return None
    return sec.float("default_feed_mm_min", above=0.0)
