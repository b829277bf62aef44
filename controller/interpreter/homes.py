"""G28/G30 (go to a stored position, through an optional intermediate point) and G28.1/G30.1."""

from __future__ import annotations

from controller.interpreter.modal import Modal
from controller.interpreter.moves import Moves
from controller.interpreter.params import G28_HOME, G30_HOME, Parameters

HOME_CODES = frozenset((280, 281, 300, 301))
_AXES = "XYZ"


class HomePositions:
    """The stored positions live in the parameters, as in LinuxCNC: #5161-#5163 (G28) and
    #5181-#5183 (G30), machine coordinates in mm (LinuxCNC's machine units). A position never
    stored is the machine origin X0 Y0 Z0 (LinuxCNC's parameter file starts at 0 too)."""

    def __init__(self, modal: Modal, moves: Moves, params: Parameters) -> None:
        self.modal = modal
        self.moves = moves
        self.params = params

    def run(self, code: int, vals: dict[str, float], lineno: int) -> None:
        base = G28_HOME if code in (280, 281) else G30_HOME
        if code in (281, 301):  # G28.1/G30.1: store where the machine stands
            for i, mm in enumerate(self.modal.pos):
                self.params.set(base + i, mm)
            return
        given = [axis for axis in _AXES if axis in vals]
        if given:  # first a traverse to the intermediate point (program frame, G90/G91)
            self.moves.line_to(self.moves.end_point(vals), True, lineno, code)
        home = [self._stored(base + i) for i in range(3)]
        pos = self.modal.pos
        # Only the axes named move on (LinuxCNC 2.9); with no axis word all of them do.
        end = tuple(home[i] if not given or axis in given else pos[i]
                    for i, axis in enumerate(_AXES))
        self.moves.line_to(end, True, lineno, code)  # type: ignore[arg-type]

    def _stored(self, number: int) -> float:
        return self.params.get(number) if self.params.is_set(number) else 0.0
