"""The two producer processes of the runtime: NC interpreter stage and reference generator stage."""

from __future__ import annotations

import ctypes
import itertools
import os
import resource
import signal
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from multiprocessing.queues import Queue
from typing import Any

from controller.blocks import LineBlock, Source
from controller.config import MachineConfig
from controller.interpreter.fifo import FAILED, drain_fifo, feed_fifo
from controller.motion.realtime import producer_nice
from controller.motion.ring import FLAG_ABORT, FLAG_FAILED, FLAG_FINAL, RefRing
from controller.motion.source import SyncMarks
from controller.refpoints import RefChunk
from controller.runtime.gc_policy import collect_less

BlocksFn = Callable[[str, MachineConfig], Iterable[Any]]
GenerateFn = Callable[[Iterable[Any], MachineConfig], Iterable[RefChunk]]


def blocks_source(path: str, config: MachineConfig,
                  start_mm: tuple[float, float, float] | None = None,
                  offsets: Any = None, from_line: int | None = None,
                  probes: Any = None) -> Iterator[Any]:
    """The interpreter stage: read_program, block by block (its process is interpreter_main);
    probes: the G38 results known (controller/probe.ProbeResults), read no further than one
    without its result."""
    from controller.interpreter.program import read_program
    from controller.offsets import ProgramOffsets
    track = None if probes is None else ProgramOffsets(probes=probes)
    yield from read_program(path, config, start_mm, offsets, from_line, track)


class BlockBatch(list):
    """Blocks that go through the NC FIFO as one item (the generator stage takes them apart):
    one put, pickle and get for BATCH_BLOCKS blocks, not each (some 20 us a block).

    A line goes as a tuple of its fields, made a LineBlock again on the other side: pickled as
    itself, each line and its Source ran dataclasses' __getstate__ and __setstate__ in Python
    (some 75,000 instructions a line between both ends, a tenth of the producers' work on a G1
    walk); the other blocks go as they are."""

    def __reduce__(self) -> tuple[Any, tuple[list[Any]]]:
        return _unpacked, ([_packed(b) for b in self],)


def _packed(block: Any) -> Any:
    if type(block) is not LineBlock:
        return block
    s = block.source
    return (block.start, block.end, block.feed_mm_s, block.rapid, block.path, s.path,
            s.first_line, s.last_line)


def _unpacked(items: list[Any]) -> BlockBatch:
    """The batch again: equal blocks (a tuple is a line, see BlockBatch)."""
    line, source = LineBlock, Source
    return BlockBatch([line(i[0], i[1], i[2], i[3], i[4], source(i[5], i[6], i[7]))
                       if type(i) is tuple else i for i in items])


BATCH_BLOCKS = 256


def checked_blocks(blocks: Iterable[Any]) -> BlocksFn:
    """The interpreter stage over the blocks the check before the run kept (the same path,
    config and offsets, read from the start): the forked interpreter inherits them instead of
    reading the program a second time, and passes them on in batches (all are in memory)."""

    def source(path: str, config: MachineConfig) -> Iterator[Any]:
        it = iter(blocks)
        while batch := list(itertools.islice(it, BATCH_BLOCKS)):
            yield BlockBatch(batch)

    return source


def _unbatched(items: Iterable[Any]) -> Iterator[Any]:
    for item in items:
        if isinstance(item, BlockBatch):
            yield from item
        else:
            yield item


def reference_source(blocks: Iterable[Any], config: MachineConfig,
                     optional_stop: bool = False) -> Iterator[RefChunk]:
    """The generator stage: the look-ahead reference-point generator (controller.generator.plan).

    optional_stop: M1 pauses like M0 (the operator's optional-stop switch); else it is passed."""
    from controller.generator.plan import generate_reference
    if optional_stop:
        blocks = (_m1_as_m0(b) for b in blocks)
    yield from generate_reference(blocks, config)


def _m1_as_m0(block: Any) -> Any:
    from controller.blocks import StopBlock, StopKind
    if isinstance(block, StopBlock) and block.kind is StopKind.OPTIONAL_PAUSE:
        return replace(block, kind=StopKind.PAUSE)
    return block


def preload_stages() -> None:
    """Import the real stages in the parent: forked children then start warm (~0.5 s saved).

    An import error is left for the child to raise and report through the normal path.
    """
    import importlib
    for name in ("controller.interpreter.program", "controller.generator.plan"):
        try:
            importlib.import_module(name)
        except ImportError:
            pass


def _die_with_parent(parent_pid: int) -> None:
    """The kernel kills this child when the thread that forked it ends (PR_SET_PDEATHSIG):
    no producer outlives a killed `cncctl run` or cncd, even one busy planning that would not
    look at its parent for a while. A parent already gone by now: exit at once."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass  # not Linux: the parent checks in every wait loop remain
    if os.getppid() != parent_pid:
        os._exit(1)


PR_SET_PDEATHSIG = 1
# Each producer's memory ceiling (RLIMIT_DATA: its heap and anonymous mappings, not the
# shared libraries): a planning bug then ends one job with MemoryError, not the PC. Plans of
# the longest programs take under 150 MB; the unit caps the whole service (MemoryMax).
PRODUCER_MEMORY_BYTES = 2 << 30


def memory_ceiling(limit_bytes: int = PRODUCER_MEMORY_BYTES) -> None:
    """Lower RLIMIT_DATA to limit_bytes more than the process holds now (a forked child
    inherits its parent's heap, which counts: a test process of 3.5 GB forked producers that
    could allocate nothing) -- never raised above what was inherited."""
    cap = _data_bytes() + limit_bytes
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    if soft == resource.RLIM_INFINITY or soft > cap:
        resource.setrlimit(resource.RLIMIT_DATA, (cap, hard))


def _data_bytes() -> int:
    """VmData of this process (what RLIMIT_DATA counts), 0 where /proc cannot say."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmData:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return 0


def _child_setup(parent_pid: int, info: Queue, stage: str) -> int:
    _die_with_parent(parent_pid)
    memory_ceiling()
    # Ctrl-C goes to the whole process group: only the motion process decides how to stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # First, before the queue's feeder thread exists (it inherits it): on a loaded machine the
    # producers keep the reference ring ahead of the card and planning the first run reaches
    # the first motion sooner. Without CAP_SYS_NICE (or a systemd LimitNICE) it is refused,
    # which costs headroom: the run's result says so.
    info.put(("sched", stage, producer_nice()))
    return parent_pid


def _should_stop(ring: RefRing, parent_pid: int) -> bool:
    return bool(ring.flags & FLAG_ABORT) or os.getppid() != parent_pid


def _report_rss(info: Queue, name: str) -> None:
    info.put(("rss_kb", name, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))


def interpreter_main(path: str, config: MachineConfig, blocks_fn: BlocksFn, nc_fifo: Queue,
                     ring: RefRing, info: Queue, parent_pid: int) -> None:
    """Process 1: NC blocks onto the bounded NC FIFO (put blocks when full: back-pressure)."""
    parent = _child_setup(parent_pid, info, "interpreter")
    try:
        items = _iter_safe(blocks_fn(path, config), info, "interpreter")
        feed_fifo(items, nc_fifo, lambda: _should_stop(ring, parent))
    finally:
        _report_rss(info, "interpreter")


def _iter_safe(items: Iterable[Any], info: Queue, stage: str) -> Iterator[Any]:
    try:
        yield from items
    except Exception as exc:  # noqa: BLE001  (any failure is reported, then the stage ends)
        info.put(("error", stage, str(exc) or type(exc).__name__))
        yield FAILED


def generator_main(config: MachineConfig, generate_fn: GenerateFn, nc_fifo: Queue,
                   ring: RefRing, info: Queue, parent_pid: int) -> None:
    """Process 2: NC blocks -> reference points into the shared-memory ring."""
    parent = _child_setup(parent_pid, info, "generator")
    collect_less()  # (gc_policy.py says why)
    try:
        marks = SyncMarks()
        blocks = _unbatched(drain_fifo(nc_fifo, lambda: _should_stop(ring, parent)))
        for chunk in generate_fn(blocks, config):
            if chunk.outputs:  # before its rows: in the motion process when they are
                info.put(("outputs", "generator", chunk.outputs))
            rows, synced = marks.rows(chunk)
            for changes in synced:  # M62's, likewise before the rows that carry its mark
                info.put(("sync_outputs", "generator", changes))
            if len(rows) and not ring.write(rows) or os.getppid() != parent:
                return
        ring.set_flag(FLAG_FINAL)
    except Exception as exc:  # noqa: BLE001  (reported on the queue, flagged in the ring)
        info.put(("error", "generator", f"{type(exc).__name__}: {exc}"))
        ring.set_flag(FLAG_FAILED)
    finally:
        _report_rss(info, "generator")
