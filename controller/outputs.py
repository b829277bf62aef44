"""The machine's outputs as state: spindle, coolant, digital and analog outputs, their safe
state, and the image of them a backend writes (digital bits and analog channels)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from controller.blocks import OutputChange
from controller.io_config import N_CHANNELS, IoConfig

SPINDLE_DIRECTIONS = ("off", "cw", "ccw")


@dataclass(frozen=True, slots=True)
class OutputImage:
    """What a backend drives: bit i of `bits` is digital output i; analog[c] is channel c."""

    bits: int = 0
    analog: tuple[float, ...] = (0.0,) * N_CHANNELS


@dataclass
class OutputState:
    """Every machine output's value; starts in the safe state of `io`."""

    io: IoConfig
    spindle: str = "off"
    spindle_rpm: float = 0.0
    coolant_mist: bool = False
    coolant_flood: bool = False
    digital: list[bool] = field(default_factory=list)
    analog: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.digital = self.digital or [d.safe for d in self.io.digital]
        self.analog = self.analog or [a.safe for a in self.io.analog]

    def to_safe(self) -> list[OutputChange]:
        """Spindle and coolant off, digital and analog outputs at their safe values; the
        changes this made (none when already safe)."""
        safe = [OutputChange("spindle", "off"), OutputChange("coolant_mist", False),
                OutputChange("coolant_flood", False)]
        safe += [OutputChange(f"digital_{i}", d.safe) for i, d in enumerate(self.io.digital)]
        safe += [OutputChange(f"analog_{i}", a.safe) for i, a in enumerate(self.io.analog)]
        return self.apply(safe)

    def apply(self, changes: tuple[OutputChange, ...] | list[OutputChange]
              ) -> list[OutputChange]:
        """Set each change; the ones that changed a value (what an event reports)."""
        changed = []
        for ch in changes:
            if self.value(ch.name) != ch.value:
                self._set(ch.name, ch.value)
                changed.append(ch)
        return changed

    def value(self, name: str) -> Any:
        kind, _, index = name.partition("_")
        if kind == "digital":
            return self.digital[int(index)]
        if kind == "analog":
            return self.analog[int(index)]
        return getattr(self, name)

    def _set(self, name: str, value: Any) -> None:
        kind, _, index = name.partition("_")
        if kind == "digital":
            self.digital[int(index)] = bool(value)
        elif kind == "analog":
            self.analog[int(index)] = float(value)
        elif name == "spindle":
            if value not in SPINDLE_DIRECTIONS:
                raise ValueError(f"spindle direction {value!r}")
            self.spindle = str(value)
        elif name in ("spindle_rpm", "coolant_mist", "coolant_flood"):
            setattr(self, name, float(value) if name == "spindle_rpm" else bool(value))
        else:
            raise ValueError(f"unknown output {name!r}")

    def as_dict(self) -> dict[str, Any]:
        """For `status` and a run's result."""
        return {"spindle": self.spindle, "spindle_rpm": self.spindle_rpm,
                "coolant_mist": self.coolant_mist, "coolant_flood": self.coolant_flood,
                "digital": list(self.digital), "analog": list(self.analog)}

    def image(self) -> OutputImage:
        """The backend's bits and channels for this state."""
        io, bits = self.io, 0
        on = self.spindle != "off"
        for bit, value in ((io.spindle.on_bit, on), (io.spindle.reverse_bit,
                           self.spindle == "ccw"), (io.mist_bit, self.coolant_mist),
                           (io.flood_bit, self.coolant_flood)):
            if bit is not None and value:
                bits |= 1 << bit
        for out, value in zip(io.digital, self.digital, strict=True):
            bits |= int(value) << out.bit
        analog = [0.0] * N_CHANNELS
        if io.spindle.speed_channel is not None:
            analog[io.spindle.speed_channel] = self.spindle_rpm if on else 0.0
        for out, value in zip(io.analog, self.analog, strict=True):
            analog[out.channel] = value
        return OutputImage(bits, tuple(analog))


def output_names(io: IoConfig) -> tuple[str, ...]:
    """Every output name of a machine (events and `status` use these)."""
    return (("spindle", "spindle_rpm", "coolant_mist", "coolant_flood")
            + tuple(f"digital_{i}" for i in range(len(io.digital)))
            + tuple(f"analog_{i}" for i in range(len(io.analog))))
