"""LinuxCNC's read-only system parameters: #5400-#5413 (tool), #5420-#5428 (position) and the
named ones (#<_x>, #<_feed>, #<_imperial>, ...), read from the interpreter's state."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

TOOL_NUMBER = 5400  # the loaded tool; #5401-#5409 the tool offsets X Y Z A B C U V W in force
TOOL_DIAMETER = 5410  # the loaded tool's diameter; #5411-#5413 lathe angles and orientation
TOOL_LAST = 5413
POSITION_FIRST = 5420  # #5420-#5428: X Y Z A B C U V W in the program frame and units
SYSTEM_LAST = 5428
_AXES = "xyzabcuvw"


class SystemParams:
    """Values LinuxCNC computes when a program reads them (never stored: always current)."""

    def __init__(self, state: Any) -> None:  # the InterpState (it imports this module)
        self.state = state
        self.named_values: dict[str, Callable[[], float]] = {
            **{f"_{axis}": self._position_of(i) for i, axis in enumerate(_AXES)},
            "_feed": lambda: state.modal.feed_mm_s * 60.0 / state.modal.scale,
            "_rpm": lambda: state.spindle_rpm,
            "_imperial": lambda: float(state.modal.scale != 1.0),
            "_metric": lambda: float(state.modal.scale == 1.0),
            "_absolute": lambda: float(state.modal.absolute),
            "_incremental": lambda: float(not state.modal.absolute),
            "_current_tool": lambda: float(state.tools.loaded),
            "_selected_tool": lambda: float(state.tools.selected),
            "_spindle_on": lambda: float(state.spindle_on),
            "_spindle_cw": lambda: float(state.spindle_code == 3),
            "_coolant_mist": lambda: float("M7" in state.coolant),
            "_coolant_flood": lambda: float("M8" in state.coolant),
            "_coord_system": lambda: float(530 + 10 * state.offsets.table.active),
            "_motion_mode": lambda: float(
                800 if state.modal.motion is None else state.modal.motion
            ),
            "_plane": lambda: float(state.modal.plane),
            "_ccomp": lambda: 400.0,  # G40: phcnc has no cutter compensation
            "_units_per_minute": lambda: 1.0,  # G94, the only feed mode
            "_inverse_time": lambda: 0.0,
            "_units_per_rev": lambda: 0.0,
            "_call_level": lambda: float(state.params.depth),
        }

    def numbered(self, number: int) -> float | None:
        """#5400-#5413 and #5420-#5428; None for any other number."""
        state = self.state
        if number == TOOL_NUMBER:
            return float(state.tools.loaded)
        if number == TOOL_NUMBER + 3:  # the tool length in force: phcnc's one tool offset
            return state.offsets.tool_mm / state.modal.scale
        if number == TOOL_DIAMETER:
            table, loaded = state.tools.table, state.tools.loaded
            tool = None if table is None or not loaded else table.get(loaded)
            return 0.0 if tool is None else tool.diameter_mm / state.modal.scale
        if TOOL_NUMBER < number <= TOOL_LAST:
            return 0.0  # offsets on other axes, lathe angles: none in phcnc
        if POSITION_FIRST <= number <= SYSTEM_LAST:
            return self._position_of(number - POSITION_FIRST)()
        return None

    def named(self, name: str) -> float | None:
        """`_x`, `_feed`, ... (lower case, as the lexer keeps names); None for other names."""
        value = self.named_values.get(name)
        return None if value is None else value()

    def _position_of(self, index: int) -> Callable[[], float]:
        def position() -> float:
            if index > 2:
                return 0.0  # axes A B C U V W: phcnc has none, LinuxCNC reads them as 0
            state = self.state
            origin = state.offsets.origin
            offset = 0.0 if origin is None else origin[index]
            return (state.modal.pos[index] - offset) / state.modal.scale

        return position


def is_system_number(number: int) -> bool:
    """A numbered parameter the program may read but not set."""
    return TOOL_NUMBER <= number <= TOOL_LAST or POSITION_FIRST <= number <= SYSTEM_LAST
