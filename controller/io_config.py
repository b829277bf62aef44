"""The `io` section of a machine config: which backend output each machine output drives."""

from __future__ import annotations

from dataclasses import dataclass

from controller.errors import ConfigError
from controller.yaml_strict import Section

N_BITS = 16  # digital outputs of a backend: bits 0-15 (the serial card's frame, 0x60FE:01)
N_CHANNELS = 4  # analog outputs of a backend: channels 0-3


@dataclass(frozen=True, slots=True)
class DigitalOutput:
    """M62-M65 P<index>: the backend bit it drives and its value in the safe state."""

    bit: int
    safe: bool = False


@dataclass(frozen=True, slots=True)
class AnalogOutput:
    """M67/M68 E<index>: the backend channel, its safe value and the range Q may take."""

    channel: int
    safe: float = 0.0
    min_value: float = -10.0
    max_value: float = 10.0


@dataclass(frozen=True, slots=True)
class SpindleIo:
    """M3/M4/M5 and S. A bit or channel of None drives nothing (the state is still kept)."""

    on_bit: int | None = None
    reverse_bit: int | None = None  # set under M4
    speed_channel: int | None = None  # the speed in rpm
    max_rpm: float = 100_000.0
    # Wait after a start, a reversal or a speed change with the spindle on, before the next
    # move: the spindle is at speed when the cut begins (LinuxCNC waits for spindle.at-speed).
    spin_up_s: float = 0.0
    # Instead of that fixed wait: stand at the start until the backend's at-speed input is
    # true (controller/motion/at_speed.py), a fault after at_speed_timeout_s.
    at_speed_input: bool = False
    at_speed_timeout_s: float = 10.0


@dataclass(frozen=True, slots=True)
class IoConfig:
    """Machine outputs -> backend outputs. Safe state: spindle off, coolant off, the digital
    and analog outputs at their `safe` values (abort, e-stop, fault)."""

    spindle: SpindleIo = SpindleIo()
    mist_bit: int | None = None  # M7
    flood_bit: int | None = None  # M8
    digital: tuple[DigitalOutput, ...] = ()
    analog: tuple[AnalogOutput, ...] = ()


def _optional_int(sec: Section, key: str, maxval: int) -> int | None:
    """An index key that may be absent or null (drives nothing)."""
    if sec.data.get(key) is None:
        sec.used.add(key)
        return None
    return sec.int(key, minval=0, maxval=maxval)


def _items(sec: Section, key: str) -> list[Section]:
    raw = sec._raw(key, [])
    if not isinstance(raw, list):
        raise ConfigError(sec.path, sec._key(key), "must be a list (index 0 is P0 / E0)")
    return [Section(item, sec.path, f"{sec._key(key)}[{i}]") for i, item in enumerate(raw)]


def _digital(sec: Section) -> DigitalOutput:
    out = DigitalOutput(bit=sec.int("bit", minval=0, maxval=N_BITS - 1),
                        safe=sec.bool("safe", False))
    sec.finish()
    return out


def _analog(sec: Section) -> AnalogOutput:
    lo = sec.float("min", -10.0)
    hi = sec.float("max", 10.0)
    if lo >= hi:
        raise ConfigError(sec.path, sec._key("min"), "must be below max")
    safe = sec.float("safe", 0.0, minval=lo, maxval=hi)
    out = AnalogOutput(channel=sec.int("channel", minval=0, maxval=N_CHANNELS - 1), safe=safe,
                       min_value=lo, max_value=hi)
    sec.finish()
    return out


def read_io(sec: Section) -> IoConfig:
    """The `io` section (optional; without it outputs are kept as state and drive nothing)."""
    sp = sec.section("spindle", {})
    spindle = SpindleIo(on_bit=_optional_int(sp, "on_bit", N_BITS - 1),
                        reverse_bit=_optional_int(sp, "reverse_bit", N_BITS - 1),
                        speed_channel=_optional_int(sp, "speed_channel", N_CHANNELS - 1),
                        max_rpm=sp.float("max_rpm", 100_000.0, above=0.0),
                        spin_up_s=sp.float("spin_up_s", 0.0, minval=0.0, maxval=60.0),
                        at_speed_input=sp.bool("at_speed_input", False),
                        at_speed_timeout_s=sp.float("at_speed_timeout_s", 10.0, above=0.0,
                                                    maxval=600.0))
    if spindle.at_speed_input and spindle.spin_up_s:
        raise ConfigError(sp.path, sp._key("spin_up_s"), "must be 0 with at_speed_input (the "
                          "input, not a fixed time, ends the spin-up)")
    sp.finish()
    cool = sec.section("coolant", {})
    mist = _optional_int(cool, "mist_bit", N_BITS - 1)
    flood = _optional_int(cool, "flood_bit", N_BITS - 1)
    cool.finish()
    cfg = IoConfig(spindle=spindle, mist_bit=mist, flood_bit=flood,
                   digital=tuple(_digital(s) for s in _items(sec, "digital")),
                   analog=tuple(_analog(s) for s in _items(sec, "analog")))
    sec.finish()
    _check_unique(cfg, sec)
    return cfg


def _check_unique(cfg: IoConfig, sec: Section) -> None:
    """Two outputs on one bit (or channel) would fight: an error naming the second."""
    bits: dict[int, str] = {}
    named = [("spindle.on_bit", cfg.spindle.on_bit), ("spindle.reverse_bit",
             cfg.spindle.reverse_bit), ("coolant.mist_bit", cfg.mist_bit),
             ("coolant.flood_bit", cfg.flood_bit)]
    named += [(f"digital[{i}].bit", d.bit) for i, d in enumerate(cfg.digital)]
    _unique(named, bits, sec)
    channels: dict[int, str] = {}
    chan = [("spindle.speed_channel", cfg.spindle.speed_channel)]
    chan += [(f"analog[{i}].channel", a.channel) for i, a in enumerate(cfg.analog)]
    _unique(chan, channels, sec)


def _unique(named: list[tuple[str, int | None]], seen: dict[int, str], sec: Section) -> None:
    for key, index in named:
        if index is None:
            continue
        if index in seen:
            raise ConfigError(sec.path, sec._key(key), f"{index} is already {seen[index]}")
        seen[index] = sec._key(key)

