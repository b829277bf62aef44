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


def output_event_text(fields: dict[str, Any]) -> str:
    """An output event for a person: 'line 3: coolant_flood on (t 1.003 s)'."""
    value = fields.get("value")
    shown = ("on" if value else "off") if isinstance(value, bool) else f"{value:g}" \
        if isinstance(value, float) else str(value)
    safe = ", safe state" if fields.get("safe") else ""
    return f"line {fields.get('line')}: {fields.get('name')} {shown} (t {fields.get('t_s')} s" \
           f"{safe})"
