"""Fault injection of the simulated CiA 402 drives (sim_drive.py): what to break, and when."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from controller.errors import DriveError
from drivers.canopen import cia402 as c

SDO_ABORT_VALUE_RANGE = 0x06090030  # "value range of parameter exceeded"


@dataclass
class Injections:
    """Fault injection for one axis; times count SYNC cycles since the first enable."""

    fault_after_s: float | None = None
    fault_code: int = c.EMCY_OVERCURRENT
    lag_mm: float = 0.0
    lag_after_s: float = 0.0
    silent_after_s: float | None = None
    sdo_abort_index: int | None = None
    estop_input_file: str | None = None  # the e-stop input is open while this file exists


def opt_int(options: dict[str, Any], key: str) -> int | None:
    value = options.get(key)
    if value is None:
        return None
    try:
        return int(value, 0) if isinstance(value, str) else int(value)
    except ValueError as exc:
        raise DriveError(f"simulated drive option {key}: {value!r} is not an integer") from exc


def opt_float(options: dict[str, Any], key: str) -> float | None:
    value = options.get(key)
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError) as exc:
        raise DriveError(f"simulated drive option {key}: {value!r} is not a number") from exc


def injections(options: dict[str, Any]) -> Injections:
    return Injections(
        fault_after_s=opt_float(options, "drive_fault_after_s"),
        fault_code=opt_int(options, "drive_fault_code") or c.EMCY_OVERCURRENT,
        lag_mm=opt_float(options, "lag_mm") or 0.0,
        lag_after_s=opt_float(options, "lag_after_s") or 0.0,
        silent_after_s=opt_float(options, "silent_after_s"),
        sdo_abort_index=opt_int(options, "sdo_abort_index"),
    )
