"""Machine outputs in the reference stream: the rows at rest where an OutputBlock is set, then
its spin-up wait."""

from __future__ import annotations

import numpy as np

from controller.blocks import OutputBlock
from controller.config import MachineConfig
from controller.refpoints import RefChunk

MARK_ROWS = 2  # the mark is on the first; the second keeps it off a program's last row


def output_mark(block: OutputBlock, config: MachineConfig, t0_s: float) -> RefChunk:
    """MARK_ROWS samples holding the block's position; the motion loop sets the outputs once
    the card has clocked the first (the machine stands there)."""
    pos = np.repeat(np.array(block.position)[None, : len(config.axis_names)], MARK_ROWS, axis=0)
    return RefChunk(t0_s + config.sample_period_s, pos, np.zeros(MARK_ROWS),
                    np.full(MARK_ROWS, block.source.first_line, np.int32),
                    outputs=block.changes)
