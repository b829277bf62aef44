"""Machine I/O of the simulated CiA 402 drives: limit switches (0x60FD and statusword bit 11)
from limit_input_file, the digital (0x60FE) and analog (0x2400) outputs, recorded to
outputs_file so a test reads back what the drives hold, the touch probe (sim_probe.py) and the
spindle's at-speed input (0x60FD bit 16, drivers/sim/spindle.py: option spindle_spinup_s)."""

from __future__ import annotations

import time
from typing import Any

from controller.io_config import SpindleIo
from drivers.canopen import cia402 as c
from drivers.canopen.sim_probe import SimTouchProbe402
from drivers.io_peer import limit_tripped, record_outputs
from drivers.sim.spindle import SimSpindle, spinup_option


class SimIo402:
    """Shared by the drives of one bus; each asks with its axis index."""

    def __init__(self, options: dict[str, Any], axes: tuple[str, ...],
                 spindle: SpindleIo) -> None:
        self.limit_file = options.get("limit_input_file")
        self.outputs_file = options.get("outputs_file")
        self.axes = axes
        self.bits = 0
        self.mask = 0
        self.analog = [0.0] * 4
        self.probe = SimTouchProbe402(options, axes)
        # every drive's 0x60FD bit 16 (the peer does not know which is the io_node)
        self.spindle = SimSpindle(spindle, spinup_option(options.get("spindle_spinup_s"),
                                                         "simulated drive option"), time.monotonic)

    def digital_inputs(self, axis: int) -> int:
        """0x60FD of axis `axis`'s drive."""
        return self._limits(axis) | (c.DI_SPINDLE_AT_SPEED if self.spindle.at_speed() else 0)

    def _limits(self, axis: int) -> int:
        tripped = limit_tripped(self.limit_file, self.axes)
        if tripped is None or tripped[0] != axis:
            return 0
        return c.DI_POSITIVE_LIMIT if tripped[1] > 0 else c.DI_NEGATIVE_LIMIT

    def statusword_bits(self, axis: int) -> int:
        limit = c.SW_INTERNAL_LIMIT if self._limits(axis) else 0
        return limit | self.probe.statusword_bits()

    def write(self, index: int, subindex: int, value: Any) -> bool:
        """An SDO write of an output object (False: not one of them)."""
        if index == c.DIGITAL_OUTPUTS and subindex in (1, 2):
            if subindex == 1:
                self.bits = int(value)
            else:
                self.mask = int(value)
        elif index == c.ANALOG_OUTPUTS and 1 <= subindex <= 4:
            self.analog[subindex - 1] = float(value)
        else:
            return False
        record_outputs(self.outputs_file, self.bits & self.mask, self.analog)
        self.spindle.written(self.bits & self.mask, self.analog)
        return True
