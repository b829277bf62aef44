"""The NC FIFO: interpreter process, bounded queue with back-pressure, errors as NcError."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from nc_helpers import XY_TABLE

from controller.errors import NcError
from controller.interpreter.fifo import NcFifo, batch_plan
from controller.interpreter.program import read_program


def _program(tmp_path: Path, n: int, tail: str = "") -> str:
    path = tmp_path / "p.nc"
    path.write_text("F600\n" + "".join(f"G1 X{i % 100} Y{i % 7}\n" for i in range(1, n)) + tail)
    return str(path)


def test_slow_consumer_keeps_the_producer_within_the_bound(tmp_path: Path) -> None:
    path = _program(tmp_path, 400)
    expected = list(read_program(path, XY_TABLE))
    ahead = []
    got = []
    with NcFifo(path, XY_TABLE, maxsize=5) as fifo:
        for block in fifo:
            got.append(block)
            if len(got) <= 25:
                time.sleep(0.02)  # the producer has time to fill the queue
                ahead.append(fifo.produced - fifo.consumed)
        assert fifo.produced == fifo.consumed == len(expected)
    assert max(ahead) <= 5  # never more than the queue bound ahead of the consumer
    assert max(ahead) == 5  # ... and it does run ahead, up to the bound
    assert got == expected


def test_batched_queue_stays_within_the_default_bound(tmp_path: Path) -> None:
    path = _program(tmp_path, 600)
    ahead = []
    fifo = NcFifo(path, XY_TABLE)
    assert fifo.maxsize == XY_TABLE.runtime.nc_fifo_blocks and fifo.batch > 1
    with fifo:
        for n, _ in enumerate(fifo):
            if n < 40:
                time.sleep(0.01)
                ahead.append(fifo.produced - fifo.consumed)
        assert fifo.consumed == 599
    assert fifo.maxsize - fifo.batch < max(ahead) <= fifo.maxsize


@pytest.mark.parametrize("max_blocks", [2, 3, 5, 8, 64, 100, 1000])
def test_batch_plan_respects_the_bound(max_blocks: int) -> None:
    batch, items = batch_plan(max_blocks)
    assert items >= 1 and items * batch + batch - 1 <= max_blocks


def test_error_arrives_as_nc_error_after_the_good_blocks(tmp_path: Path) -> None:
    path = _program(tmp_path, 4, tail="G1 X1 Y1 Q5\n")
    blocks = []
    with NcFifo(path, XY_TABLE) as fifo, pytest.raises(NcError) as info:
        for block in fifo:
            blocks.append(block)
    assert len(blocks) == 3
    assert (info.value.line, info.value.col, info.value.word) == (5, 10, "Q5")
    assert info.value.format().startswith(f"{path}:5:10: error: Q word")


def test_close_early_stops_the_producer(tmp_path: Path) -> None:
    fifo = NcFifo(_program(tmp_path, 2000), XY_TABLE, maxsize=2).start()
    it = iter(fifo)
    next(it)
    proc = fifo._proc
    t0 = time.perf_counter()
    fifo.close()
    assert time.perf_counter() - t0 < 5 and not proc.is_alive()
