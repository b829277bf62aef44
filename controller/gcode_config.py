"""The `gcode` section of a machine config: the folders `o<name> call` searches for name.ngc."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from controller.errors import ConfigError


@dataclass(frozen=True, slots=True)
class GcodeConfig:
    """subroutine_path: folders (absolute) searched, after the program's own folder, for the
    file `name.ngc` of an `o<name> call` whose subroutine the program does not hold (LinuxCNC's
    [RS274NGC]SUBROUTINE_PATH)."""

    subroutine_path: tuple[str, ...] = ()


def read_gcode_section(sec: Any) -> GcodeConfig:
    """The section (a yaml_strict Section); folders relative to the config's folder must exist."""
    raw = sec._raw("subroutine_path", [])
    key = sec._key("subroutine_path")
    if not isinstance(raw, list) or not all(isinstance(d, str) and d for d in raw):
        raise ConfigError(sec.path, key, "must be a list of folder names")
    base = os.path.dirname(os.path.abspath(sec.path))
    folders = tuple(os.path.join(base, os.path.expanduser(d)) for d in raw)
    for name, folder in zip(raw, folders, strict=True):
        if not os.path.isdir(folder):
            raise ConfigError(sec.path, key, f"{name}: no such folder")
    sec.finish()
    return GcodeConfig(folders)
