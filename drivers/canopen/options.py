"""The canopen backend's options (config drive.options, strict) with their defaults and checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from controller.config import MachineConfig
from controller.errors import DriveError


@dataclass(frozen=True)
class CanopenOptions:
    """Parsed drive.options of the canopen backend (units in the names)."""

    interface: str
    channel: str
    bitrate: int
    node_ids: tuple[int, ...]
    counts_per_mm: tuple[float, ...]
    master_node_id: int
    master_heartbeat_ms: int  # our heartbeat period
    drive_heartbeat_ms: int  # 0x1017 of each drive
    heartbeat_timeout_ms: int  # both ways: 0x1016 on the drive, our check of the drive's
    ferror_window_mm: float  # 0x6065 (converted to counts)
    ferror_timeout_ms: int  # 0x6066
    tpdo_timeout_cycles: int  # SYNCs without a TPDO from a drive before it counts as lost
    fifo_frames: int
    sdo_timeout_s: float
    home_offset_sign: int = 1  # -1: a drive whose home point reads -0x607C (docs/canopen.md)
    io_node: int = 1  # the drive whose outputs (0x60FE, 0x2400) are the machine's outputs
    touch_probe: bool = False  # a probe wired to every drive's touch probe input (G38)


DEFAULTS: dict[str, Any] = {
    "interface": "slcan", "channel": "/dev/ttyACM0", "bitrate": 1_000_000,
    "node_ids": None, "counts_per_mm": None, "master_node_id": 127,
    "master_heartbeat_ms": 50, "drive_heartbeat_ms": 50, "heartbeat_timeout_ms": 300,
    "ferror_window_mm": 1.0, "ferror_timeout_ms": 10, "tpdo_timeout_cycles": 100,
    "fifo_frames": 256, "sdo_timeout_s": 0.3, "home_offset_sign": 1, "io_node": None,
    "touch_probe": False,
}
# realtime: make_drive passes it; the bus has its own clock, so virtual time is refused.
OPTIONS = frozenset(DEFAULTS) | {"realtime"}


def _int(key: str, value: Any, lo: int, hi: int) -> int:
    try:
        out = int(value, 0) if isinstance(value, str) else int(value)
    except (TypeError, ValueError) as exc:
        raise DriveError(f"canopen option {key}: {value!r} is not an integer") from exc
    if not lo <= out <= hi or (not isinstance(value, str) and out != value):
        raise DriveError(f"canopen option {key}: {value!r} is not an integer in {lo}..{hi}")
    return out


def _float(key: str, value: Any, above: float = 0.0) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise DriveError(f"canopen option {key}: {value!r} is not a number") from exc
    if not out > above:
        raise DriveError(f"canopen option {key}: {value!r} must be above {above:g}")
    return out


def _per_axis(key: str, value: Any, n_axes: int) -> list[Any]:
    if not isinstance(value, (list, tuple)) or len(value) != n_axes:
        raise DriveError(f"canopen option {key}: expected a list of {n_axes} values (one per "
                         f"axis), got {value!r}")
    return list(value)


def parse_options(config: MachineConfig, options: dict[str, Any]) -> CanopenOptions:
    """Check every key (unknown -> DriveError naming it) and fill the defaults."""
    unknown = sorted(set(options) - OPTIONS)
    if unknown:
        raise DriveError(f"unknown canopen option(s): {', '.join(unknown)} "
                         f"(have: {', '.join(sorted(OPTIONS))})")
    if options.get("realtime", True) is False:
        raise DriveError("the canopen backend runs on the bus's own clock (SYNC every "
                         "sample period): virtual time (realtime=False, --virtual-time) is "
                         "not available; use the sim backend for that")
    o = DEFAULTS | {k: v for k, v in options.items() if k != "realtime"}
    n = len(config.axes)
    node_ids = tuple(_int("node_ids", v, 1, 127) for v in _per_axis(
        "node_ids", o["node_ids"] if o["node_ids"] is not None else list(range(1, n + 1)), n))
    if len(set(node_ids)) != n:
        raise DriveError(f"canopen option node_ids: {list(node_ids)} repeats a node id")
    cpm_default = [1.0 / a.pulse_mm for a in config.axes]
    cpm = tuple(_float("counts_per_mm", v) for v in _per_axis(
        "counts_per_mm", o["counts_per_mm"] if o["counts_per_mm"] is not None else cpm_default,
        n))
    master = _int("master_node_id", o["master_node_id"], 1, 127)
    sign = _int("home_offset_sign", o["home_offset_sign"], -1, 1)
    if sign == 0:
        raise DriveError("canopen option home_offset_sign: must be 1 or -1")
    if master in node_ids:
        raise DriveError(f"canopen option master_node_id: {master} is also a drive's node id")
    io_node = node_ids[0] if o["io_node"] is None else _int("io_node", o["io_node"], 1, 127)
    if io_node not in node_ids:
        raise DriveError(f"canopen option io_node: {io_node} is not one of the drives' node "
                         f"ids {list(node_ids)}")
    return CanopenOptions(
        interface=str(o["interface"]), channel=str(o["channel"]),
        bitrate=_int("bitrate", o["bitrate"], 10_000, 1_000_000),
        node_ids=node_ids, counts_per_mm=cpm, master_node_id=master,
        master_heartbeat_ms=_int("master_heartbeat_ms", o["master_heartbeat_ms"], 1, 10_000),
        drive_heartbeat_ms=_int("drive_heartbeat_ms", o["drive_heartbeat_ms"], 1, 10_000),
        heartbeat_timeout_ms=_int("heartbeat_timeout_ms", o["heartbeat_timeout_ms"], 1, 65_535),
        ferror_window_mm=_float("ferror_window_mm", o["ferror_window_mm"]),
        ferror_timeout_ms=_int("ferror_timeout_ms", o["ferror_timeout_ms"], 0, 65_535),
        tpdo_timeout_cycles=_int("tpdo_timeout_cycles", o["tpdo_timeout_cycles"], 2, 100_000),
        fifo_frames=_int("fifo_frames", o["fifo_frames"], 16, 1_000_000),
        sdo_timeout_s=_float("sdo_timeout_s", o["sdo_timeout_s"]), home_offset_sign=sign,
        io_node=io_node, touch_probe=_bool("touch_probe", o["touch_probe"]))


def _bool(key: str, value: Any) -> bool:
    if not isinstance(value, bool) and value not in ("true", "false"):
        raise DriveError(f"canopen option {key}: {value!r} is not true or false")
    return value in (True, "true")


def drive_layout(config: MachineConfig) -> CanopenOptions:
    """The bus layout of a canopen config (node ids, scaling, master id) for its simulator;
    only the config's own options count (the controller's channel is not the simulator's)."""
    options = dict(config.drive.options)
    return parse_options(config, {k: v for k, v in options.items() if k in OPTIONS})
