"""The outputs a line sets (M3-M5 with S, M7-M9, M62-M65, M67, M68) as one OutputBlock,
checked against the config's `io` map before any motion."""

from __future__ import annotations

from controller.blocks import OutputBlock, OutputChange, Point3, Source
from controller.config import MachineConfig
from controller.interpreter.codes import WordError

DIGITAL_SYNC, DIGITAL_NOW = (62, 63), (64, 65)  # on, off: with the next move / at once
ANALOG_SYNC, ANALOG_NOW = 67, 68
IO_M_CODES = frozenset((3, 4, 5, 7, 8, 9, 62, 63, 64, 65, 67, 68))
M_LETTERS = {62: frozenset("P"), 63: frozenset("P"), 64: frozenset("P"), 65: frozenset("P"),
             67: frozenset("EQ"), 68: frozenset("EQ"), 61: frozenset("Q")}  # M61 Q: tool.py
_DIRECTIONS = {3: "cw", 4: "ccw", 5: "off"}


class ProgramOutputs:
    """The outputs as the program has set them so far: a line's block holds only what it
    changes, and a spindle start, reversal or speed change waits io.spindle.spin_up_s."""

    def __init__(self, config: MachineConfig) -> None:
        self.io = config.io
        self.spindle = "off"
        self.rpm = 0.0
        self.coolant = False  # mist or flood on
        self.values: dict[str, object] = {}  # every output the program has set, as set
        self.synced: list[OutputChange] = []  # the line's M62/M63/M67: with the next move

    def line_block(self, ms: list[int], vals: dict[str, float], rpm: float | None,
                   position: Point3, source: Source) -> OutputBlock | None:
        """The line's OutputBlock (None when it sets no output). rpm: the S in force (None
        under G96, where S is a surface speed)."""
        changes: list[OutputChange] = []
        self.synced = []
        wait = self._spindle(ms, vals, rpm, changes)
        for m in ms:
            if m in (7, 8, 9):
                self.coolant = m != 9
            if m in (7, 8):
                changes.append(OutputChange("coolant_mist" if m == 7 else "coolant_flood", True))
            elif m == 9:
                changes += [OutputChange("coolant_mist", False),
                            OutputChange("coolant_flood", False)]
            elif m in DIGITAL_SYNC + DIGITAL_NOW:
                to = self.synced if m in DIGITAL_SYNC else changes
                to.append(OutputChange(f"digital_{self._digital(vals, m)}", m in (62, 64)))
            elif m in (ANALOG_SYNC, ANALOG_NOW):
                index, value = self._analog(vals, m)
                to = self.synced if m == ANALOG_SYNC else changes
                to.append(OutputChange(f"analog_{index}", value))
        self.values.update((ch.name, ch.value) for ch in self.synced)
        if not changes:
            return None
        self.values.update((ch.name, ch.value) for ch in changes)
        return OutputBlock(tuple(changes), position,
                           self.io.spindle.spin_up_s if wait else 0.0, source)

    def synced_block(self, position: Point3, source: Source) -> OutputBlock | None:
        """The line's M62/M63/M67 changes (after line_block): set with the next move."""
        if not self.synced:
            return None
        return OutputBlock(tuple(self.synced), position, 0.0, source, synced=True)

    def spindle_off(self, position: Point3, source: Source) -> OutputBlock | None:
        """M6 (a manual tool change): the spindle stopped first (None: it is)."""
        if self.spindle == "off":
            return None
        self.spindle = "off"
        self.values["spindle"] = "off"
        return OutputBlock((OutputChange("spindle", "off"),), position, 0.0, source)

    def program_end(self, position: Point3, source: Source) -> OutputBlock | None:
        """M2/M30 (as LinuxCNC): spindle stopped and coolant off (None: they are)."""
        if self.spindle == "off" and not self.coolant:
            return None
        self.spindle, self.coolant = "off", False
        self.values.update(spindle="off", coolant_mist=False, coolant_flood=False)
        return OutputBlock((OutputChange("spindle", "off"), OutputChange("coolant_mist", False),
                            OutputChange("coolant_flood", False)), position, 0.0, source)

    def restore_block(self, position: Point3, source: Source) -> OutputBlock | None:
        """Run from line N: the outputs the lines before it set, set again where it starts
        (the spindle at speed before the first cut, as LinuxCNC's run from line)."""
        if not self.values:
            return None
        changes = tuple(OutputChange(name, value) for name, value in self.values.items())  # type: ignore[arg-type]
        wait = self.io.spindle.spin_up_s if self.spindle != "off" else 0.0
        return OutputBlock(changes, position, wait, source)

    def _spindle(self, ms: list[int], vals: dict[str, float], rpm: float | None,
                 changes: list[OutputChange]) -> bool:
        """Spindle changes of the line; True when the spindle must come to speed."""
        direction = next((_DIRECTIONS[m] for m in ms if m in _DIRECTIONS), self.spindle)
        if rpm is not None and rpm > self.io.spindle.max_rpm:
            raise WordError("S", f"S{rpm:g} is above the spindle's {self.io.spindle.max_rpm:g} "
                                 "rpm (io.spindle.max_rpm)")
        new_rpm = rpm if rpm is not None and "S" in vals else self.rpm
        speed_changed = new_rpm != self.rpm
        if speed_changed:
            changes.append(OutputChange("spindle_rpm", new_rpm))
        started = direction != self.spindle
        if started:
            changes.append(OutputChange("spindle", direction))
        self.spindle, self.rpm = direction, new_rpm
        return direction != "off" and (started or speed_changed)

    def _digital(self, vals: dict[str, float], m: int) -> int:
        return _mapped(vals, "P", m, len(self.io.digital), "digital")

    def _analog(self, vals: dict[str, float], m: int) -> tuple[int, float]:
        index = _mapped(vals, "E", m, len(self.io.analog), "analog")
        if "Q" not in vals:
            raise WordError(f"M{m}", f"M{m} needs Q (the value)")
        out = self.io.analog[index]
        if not out.min_value <= vals["Q"] <= out.max_value:
            raise WordError("Q", f"M{m} E{index} Q{vals['Q']:g} is outside "
                                 f"[{out.min_value:g}, {out.max_value:g}] (io.analog[{index}])")
        return index, float(vals["Q"])


def _mapped(vals: dict[str, float], letter: str, m: int, count: int, kind: str) -> int:
    """The output the word names, one of the `count` the config's io.<kind> maps."""
    index = _index(vals, letter, m)
    if index >= count:
        mapped = f"{letter}0-{letter}{count - 1}" if count else "none"
        raise WordError(letter, f"M{m} {letter}{index}: no {kind} output {index} in the "
                                f"config's io.{kind} (mapped: {mapped})")
    return index


def _index(vals: dict[str, float], letter: str, m: int) -> int:
    if letter not in vals:
        raise WordError(f"M{m}", f"M{m} needs {letter} (the output number)")
    value = vals[letter]
    if value < 0 or value != int(value):
        raise WordError(letter, f"M{m} {letter} must be a non-negative integer")
    return int(value)
