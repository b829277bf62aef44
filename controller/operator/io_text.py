"""The machine outputs as one line of text for `cncctl status`."""

from __future__ import annotations

from typing import Any


def outputs_text(o: dict[str, Any]) -> str:
    """'spindle cw 1000 rpm, coolant flood, digital P0 on P1 off, analog E0 2.5'."""
    spindle = o.get("spindle", "off")
    parts = [f"spindle {spindle}" + (f" {o.get('spindle_rpm', 0.0):g} rpm"
                                     if spindle != "off" else "")]
    coolant = [name for name in ("mist", "flood") if o.get(f"coolant_{name}")]
    parts.append("coolant " + (" ".join(coolant) if coolant else "off"))
    digital = o.get("digital") or []
    if digital:
        parts.append("digital " + " ".join(f"P{i} {'on' if v else 'off'}"
                                           for i, v in enumerate(digital)))
    analog = o.get("analog") or []
    if analog:
        parts.append("analog " + " ".join(f"E{i} {v:g}" for i, v in enumerate(analog)))
    return ", ".join(parts)
