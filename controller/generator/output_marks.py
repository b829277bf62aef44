"""Machine outputs in the reference stream: the rows at rest where an OutputBlock is set, then
its spin-up wait; and the marks of outputs set with the next move (M62/M63/M67)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from controller.blocks import (
    ArcBlock,
    HelixBlock,
    LineBlock,
    NurbsBlock,
    OutputBlock,
    OutputChange,
    ProbeBlock,
)
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


@dataclass(frozen=True, slots=True)
class SyncMark:
    """M62/M63/M67's changes, set at the first sample of `line` (the next move) on."""

    line: int
    changes: tuple[OutputChange, ...]

    def chunk(self, config: MachineConfig, t0_s: float) -> RefChunk:
        """A chunk of no rows naming the line: it goes ahead of that line's rows."""
        n = len(config.axis_names)
        return RefChunk(t0_s, np.zeros((0, n)), np.zeros(0), np.zeros(0, np.int32),
                        sync_outputs=(self.line, self.changes))


MOVES = (LineBlock, ArcBlock, HelixBlock, NurbsBlock, ProbeBlock)  # M62 goes with these


def with_synced(blocks: Iterable[Any]) -> Iterator[Any]:
    """The blocks with each run of M62/M63/M67 blocks taken out: a SyncMark ahead of the move
    that follows, or, when no move follows before another block, an OutputBlock set at rest
    there (LinuxCNC sets them with the next motion; a stop comes first here)."""
    held: list[OutputBlock] = []
    for block in blocks:
        if isinstance(block, OutputBlock) and block.synced:
            held.append(block)
            continue
        if held:
            changes = tuple(ch for b in held for ch in b.changes)
            yield SyncMark(block.source.first_line, changes) if isinstance(block, MOVES) else \
                replace(held[-1], changes=changes, synced=False)
            held = []
        yield block
    if held:
        yield replace(held[-1], changes=tuple(ch for b in held for ch in b.changes),
                      synced=False)
