"""What operators read: positions, pulse counts and offset tables as words and numbers."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from controller.offsets import SYSTEM_NAMES


def axes_text(values_mm: Mapping[str, float], digits: int = 3, unit: str = "mm") -> str:
    """`X 9.999 Y 0.000 mm`; `unknown` for no axes."""
    if not values_mm:
        return "unknown"
    words = " ".join(f"{axis.upper()} {float(v):.{digits}f}" for axis, v in values_mm.items())
    return f"{words} {unit}".rstrip()


def pulses_text(pulses: Mapping[str, Mapping[str, int]]) -> str:
    """`X 1200 Y -300 (all executed)`, or each axis's executed of commanded when they differ."""
    if not pulses:
        return "none"
    if all(p["commanded"] == p["executed"] for p in pulses.values()):
        return " ".join(f"{a.upper()} {p['executed']}" for a, p in pulses.items()) + \
            " (all executed)"
    return ", ".join(f"{a.upper()} {p['executed']} executed of {p['commanded']} commanded"
                     for a, p in pulses.items())


def offsets_table(offsets: Mapping[str, Any], axes: Sequence[str]) -> str:
    """The daemon's work offsets (`cncctl status --json`'s `offsets`) for the machine's axes:
    one row per system, the active one marked, then G92 and the origin in force."""
    width = 10
    head = "work offsets (mm)".ljust(18) + "".join(a.upper().rjust(width) for a in axes)
    active = offsets.get("active", "")

    def row(label: str, point: Mapping[str, float]) -> str:
        return label.ljust(18) + "".join(f"{float(point.get(a, 0.0)):{width}.3f}" for a in axes)

    systems = offsets.get("systems_mm", {})
    rows = [head] + [row(name + ("  active" if name == active else ""), systems.get(name, {}))
                     for name in SYSTEM_NAMES if name in systems]
    rows.append(row("G92", offsets.get("g92_mm", {})))
    rows.append(row("work origin", offsets.get("work_origin_mm", {})))
    return "\n".join(rows)


def fields_text(fields: Mapping[str, Any]) -> str:
    """An event's fields as words: `program nc_programs/a.nc, drive sim, virtual time yes`."""
    def word(value: Any) -> str:
        if isinstance(value, bool):
            return "yes" if value else "no"
        if value is None:
            return "none"
        if isinstance(value, float):
            return f"{value:g}"
        return str(value)
    return ", ".join(f"{key.replace('_', ' ')} {word(value)}" for key, value in fields.items())
