"""The sim card clocked a block at a time in virtual time, a block taken back after a fault."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from drivers.base import Feedback


class BlockClock:
    """SimCard's virtual-time blocks (controller/motion/blocks.py says why): the state that
    clocking changes is kept before a block and put back when the host would have acted
    inside it. Mixed into SimCard, whose lock, FIFO, axes and trace it uses."""

    def advance_until(self, n_frames: int, cut: Callable[[Feedback], int | None], step: int) -> int:
        """Clock up to n periods at once. cut(the block's feedback) names how many of its rows
        a host clocking `step` periods a cycle would have read before it acted (a fault seen),
        or None; the block is then taken back and clocked again only to the end of that
        cycle, so that what follows is as cycle by cycle. Returns the periods clocked."""
        card: Any = self
        with card._lock:
            if card._homing_run is not None:
                card._clock(n_frames)
                return n_frames
            if card.frame_outputs.waiting:  # M62's outputs are set as their frame is clocked:
                card._clock(step)  # their effects (a file, events) cannot be taken back
                return step
            snap = self._snapshot()
            card._clock(n_frames)
            block = self._block_feedback(card._trace[snap[1] :])
            rows = cut(block)
            keep = n_frames if rows is None else min(n_frames, -(-rows // step) * step)
            if keep < n_frames:
                self._restore(snap)
                card._clock(keep)
            elif len(block):  # read back as the cut saw it: the same arrays, joined once
                card._trace[snap[1] :] = [(block.seq, block.commanded_counts, block.encoder_counts)]
            return keep

    def _block_feedback(self, trace: list[tuple[np.ndarray, ...]]) -> Feedback:
        if trace:
            return Feedback(*(np.concatenate(part) for part in zip(*trace, strict=True)))
        empty = np.zeros((0, len(self._axes.commanded)), dtype=np.int64)  # type: ignore[attr-defined]
        return Feedback(np.zeros(0, dtype=np.int64), empty, empty.copy())

    def _snapshot(self) -> tuple[Any, ...]:
        """What clocking changes (the lock held, the FIFO not written meanwhile)."""
        card: Any = self
        return (
            card._axes.snapshot(),
            len(card._trace),
            len(card._fifo),
            card.frames_clocked,
            card._status,
            list(card._messages),
            card._streaming,
        )

    def _restore(self, snap: tuple[Any, ...]) -> None:
        card: Any = self
        axes, traced, queued, clocked, status, messages, streaming = snap
        card._axes.restore(axes)
        del card._trace[traced:]
        card._fifo.unpop(queued - len(card._fifo))
        card.frames_clocked, card._status, card._messages, card._streaming = (
            clocked,
            status,
            messages,
            streaming,
        )
