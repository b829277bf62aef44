"""The NC FIFO: the bounded queue of NC blocks from the interpreter process to the generator.

Both ends live here. `feed_fifo` runs in the interpreter process: it puts every item and then
END, and blocks while the queue is full (back-pressure: at most the queue's size in blocks is
ever ahead of the generator, so memory stays bounded on any program length). `drain_fifo` runs
in the generator process and yields the items until END. While waiting, each side asks its
caller's `should_stop` every POLL_S (the runtime's abort flag, a dead parent), so neither can
hang on a peer that is gone.
"""

from __future__ import annotations

import itertools
import queue
from collections.abc import Callable, Iterable, Iterator
from typing import Any

END = "__end__"  # last item on the NC FIFO after the final block
FAILED = "__failed__"  # the interpreter raised; the runtime carries its message separately
POLL_S = 0.02  # how often a waiting side looks for a stop
FAILED_MESSAGE = "NC interpreter failed"  # the generator's error when its input failed


def feed_fifo(items: Iterable[Any], fifo: Any, should_stop: Callable[[], bool]) -> bool:
    """Put every item, then END; False if asked to stop first (the rest is dropped)."""
    for item in itertools.chain(items, [END]):
        while True:
            if should_stop():
                return False
            try:
                fifo.put(item, timeout=POLL_S)
                break
            except queue.Full:
                continue
    return True


def drain_fifo(fifo: Any, should_stop: Callable[[], bool]) -> Iterator[Any]:
    """The items up to END; RuntimeError on FAILED; SystemExit(0) when asked to stop."""
    while True:
        try:
            item = fifo.get(timeout=POLL_S)
        except queue.Empty:
            if should_stop():
                raise SystemExit(0) from None
            continue
        if isinstance(item, str) and item == END:
            return
        if isinstance(item, str) and item == FAILED:
            raise RuntimeError(FAILED_MESSAGE)
        yield item
