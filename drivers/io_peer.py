"""Machine I/O of the simulated hardware (the sim card and both peers): limit switch inputs a
test trips through a file, the outputs recorded to a file a test reads back, and the work a
probe meets."""

from __future__ import annotations

import json
import math
import os
from typing import Any

from controller.errors import DriveError
from controller.probe import Workpiece

# spindle_spinup_s: the simulated at-speed input (drivers/sim/spindle.py)
IO_OPTIONS = frozenset({"limit_input_file", "outputs_file", "spindle_spinup_s"})


def limit_tripped(path: str | None, axes: tuple[str, ...]) -> tuple[int, int] | None:
    """limit_input_file: while it exists the limit switch it names ("x+", "y-") is tripped;
    (axis index, +1 or -1), or None. An unreadable or unknown name trips X's negative switch:
    an input whose name cannot be read is still an input that is open."""
    if not path or not os.path.exists(path):
        return None
    try:
        with open(path, encoding="ascii") as fh:
            text = fh.read().strip().lower()
    except (OSError, UnicodeDecodeError):
        text = ""
    if len(text) == 2 and text[0] in axes and text[1] in "+-":
        return axes.index(text[0]), 1 if text[1] == "+" else -1
    return 0, -1


def switch_name(axis: str, direction: int) -> str:
    """'X+ limit switch'."""
    return f"{axis.upper()}{'+' if direction > 0 else '-'} limit switch"


def record_outputs(path: str | None, bits: int, analog: tuple[float, ...] | list[float]) -> None:
    """outputs_file: the outputs as the hardware holds them now, as JSON (written whole, then
    renamed, so a reader never sees half of it)."""
    if not path:
        return
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w", encoding="ascii") as fh:
        json.dump({"bits": int(bits), "analog": [float(v) for v in analog]}, fh)
    os.replace(tmp, path)


def read_outputs(path: str) -> dict[str, Any] | None:
    """What record_outputs wrote last (None: nothing yet)."""
    try:
        with open(path, encoding="ascii") as fh:
            return json.load(fh)
    except FileNotFoundError:
        return None


def switch_side(name: str, axes: tuple[str, ...]) -> tuple[int, int] | None:
    """switch_name read back: (axis index, +1 or -1), or None for another text."""
    head = name[:2].lower()
    if len(head) == 2 and head[0] in axes and head[1] in "+-" and name.endswith("limit switch"):
        return axes.index(head[0]), 1 if head[1] == "+" else -1
    return None


def workpiece_option(value: Any, who: str) -> Workpiece | None:
    """probe_workpiece_mm: `x0,y0,z0,x1,y1,z1` (text or six numbers), the simulated work's box
    in machine mm (the sim card's and the peers' probe input); a DriveError naming the option
    otherwise."""
    if value is None:
        return None
    parts = value.split(",") if isinstance(value, str) else value
    try:
        v = [float(p) for p in parts]
    except (TypeError, ValueError):
        v = []
    if len(v) != 6 or not all(map(math.isfinite, v)) or any(v[i] > v[i + 3] for i in range(3)):
        raise DriveError(f"{who} probe_workpiece_mm: {value!r} is not a box "
                         "x0,y0,z0,x1,y1,z1 (mm, each min at most its max)")
    return Workpiece((v[0], v[1], v[2]), (v[3], v[4], v[5]))
