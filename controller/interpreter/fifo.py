"""The NC FIFO: the interpreter in its own process, feeding a bounded queue of NC blocks.

At most `config.runtime.nc_fifo_blocks` blocks are ever ahead of the consumer: when it is slow the
producer blocks in `put`, so memory does not grow (back-pressure). Blocks travel in batches (up to
32) because one pickled message per block would cost more than parsing it. Usage:

    with NcFifo(path, config) as fifo:   # or fifo = NcFifo(path, config).start() ... fifo.close()
        for block in fifo: ...
"""

from __future__ import annotations

import multiprocessing as mp
import queue as queue_mod
from collections.abc import Iterator
from typing import Any

from controller.blocks import NcBlock
from controller.config import MachineConfig
from controller.errors import CncError, NcError
from controller.interpreter.program import read_program

_END = ("end",)  # messages are tuples; blocks travel as lists
_POLL_S = 0.2
_MAX_BATCH = 32


def batch_plan(max_blocks: int) -> tuple[int, int]:
    """(blocks per batch, batches in the queue) so that queue plus the consumer's current
    batch never hold more than max_blocks: items * batch + (batch - 1) <= max_blocks."""
    batch = max(1, min(_MAX_BATCH, max_blocks // 4))
    return batch, max(1, (max_blocks - batch + 1) // batch)


def _put(q: Any, produced: Any, batch: list[NcBlock]) -> None:
    q.put(batch)
    with produced.get_lock():
        produced.value += len(batch)


def _produce(path: str, config: MachineConfig, q: Any, produced: Any, size: int) -> None:
    """Producer process body: every block, then the end marker, or the error as plain data."""
    batch: list[NcBlock] = []
    try:
        for block in read_program(path, config):
            batch.append(block)
            if len(batch) >= size:
                _put(q, produced, batch)
                batch = []
        if batch:
            _put(q, produced, batch)
        q.put(_END)
    except NcError as exc:
        if batch:
            _put(q, produced, batch)  # the good blocks before the error still arrive
        q.put(("nc-error", exc.path, exc.line, exc.col, exc.word, exc.message))
    except BaseException as exc:  # noqa: BLE001 - forwarded to the consumer as a message
        q.put(("crash", f"{type(exc).__name__}: {exc}"))


class NcFifo:
    """Consumer side of the NC block queue (spawn-safe: works on every platform)."""

    def __init__(self, path: str, config: MachineConfig, maxsize: int | None = None) -> None:
        self.path = path
        self.config = config
        self.maxsize = maxsize or config.runtime.nc_fifo_blocks
        self.batch, self._items = batch_plan(self.maxsize)
        self._ctx = mp.get_context("spawn")
        self._queue: Any = None
        self._proc: Any = None
        self._produced: Any = None
        self.consumed = 0
        self._done = False

    def start(self) -> NcFifo:
        self._queue = self._ctx.Queue(maxsize=self._items)
        self._produced = self._ctx.Value("q", 0)
        self._proc = self._ctx.Process(
            target=_produce,
            args=(self.path, self.config, self._queue, self._produced, self.batch),
            name="nc-interpreter", daemon=True)
        self._proc.start()
        return self

    @property
    def produced(self) -> int:
        """Blocks the producer has handed to the queue so far."""
        return int(self._produced.value) if self._produced is not None else 0

    def __iter__(self) -> Iterator[NcBlock]:
        while not self._done:
            item = self._get()
            if isinstance(item, tuple):
                self._done = True
                self._raise_if_error(item)
                return
            for block in item:
                self.consumed += 1
                yield block

    def _get(self) -> Any:
        if self._queue is None:
            raise CncError("NcFifo.start() was not called")
        while True:
            try:
                return self._queue.get(timeout=_POLL_S)
            except queue_mod.Empty:
                if not self._proc.is_alive() and self._queue.empty():
                    self._done = True
                    raise CncError(f"interpreter process for {self.path} ended without "
                                   f"finishing (exit code {self._proc.exitcode})") from None

    @staticmethod
    def _raise_if_error(item: tuple) -> None:
        if item[0] == "nc-error":
            raise NcError(*item[1:])
        if item[0] == "crash":
            raise CncError(f"interpreter process failed: {item[1]}")

    def close(self) -> None:
        """Stop the producer (if still running) and release the queue."""
        if self._proc is not None:
            if self._proc.is_alive():
                self._proc.terminate()
            self._proc.join(timeout=5)
            self._proc = None
        if self._queue is not None:
            self._queue.close()
            self._queue.cancel_join_thread()
            self._queue = None

    def __enter__(self) -> NcFifo:
        return self.start() if self._proc is None else self

    def __exit__(self, *exc: object) -> None:
        self.close()
