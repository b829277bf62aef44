"""The NC FIFO's block batches: lines sent as tuples of their fields come back equal blocks."""

from __future__ import annotations

import multiprocessing as mp
import pickle
from pathlib import Path

from runtime_helpers import xy_config

from controller.interpreter.program import read_program
from controller.runtime.stages import BlockBatch, _unbatched

CFG = xy_config()
PROGRAM = """G21 G90 G64 P0.01 F1200
G0 X1 Y1
G1 X2 Y1.5
G1 X2.25 Y3 F600
G2 X3.25 Y3 I0.5 J0
G4 P0.5
G1 X0 Y0
M0
G1 X1 F300 (a line after a pause)
M2
"""


def _blocks(tmp_path: Path) -> list:
    program = tmp_path / "mixed.nc"
    program.write_text(PROGRAM)
    return list(read_program(str(program), CFG))


def test_a_batch_pickles_lines_as_their_fields_and_comes_back_equal(tmp_path: Path) -> None:
    blocks = _blocks(tmp_path)
    kinds = {type(b).__name__ for b in blocks}
    assert {"LineBlock", "ArcBlock", "DwellBlock", "StopBlock"} <= kinds
    data = pickle.dumps(BlockBatch(blocks), protocol=pickle.HIGHEST_PROTOCOL)
    # Pickled as itself a line names its class; as its fields, only the batch's rebuild does.
    assert data.count(b"LineBlock") <= 1
    back = pickle.loads(data)
    assert type(back) is BlockBatch
    assert back == blocks
    assert [type(b) for b in back] == [type(b) for b in blocks]
    assert all(b.source == a.source for a, b in zip(blocks, back, strict=True))
    assert list(_unbatched([back, blocks[0]])) == [*blocks, blocks[0]]


def test_a_batch_through_a_real_queue_to_another_process(tmp_path: Path) -> None:
    """Through the NC FIFO's kind of queue (pickled by its feeder thread, read in a forked
    process): the child holds the parent's blocks, lines made again as LineBlocks."""
    blocks = _blocks(tmp_path)
    ctx = mp.get_context("fork")
    there, back = ctx.Queue(), ctx.Queue()
    child = ctx.Process(target=_echo, args=(there, back))
    child.start()
    try:
        there.put(BlockBatch(blocks))
        kinds, echoed = back.get(timeout=30)
    finally:
        child.join(timeout=30)
        if child.is_alive():
            child.kill()
            child.join()
    assert kinds == [type(b).__name__ for b in blocks]
    assert echoed == blocks


def _echo(there: mp.Queue, back: mp.Queue) -> None:
    batch = there.get(timeout=30)  # the blocks as the child rebuilt them, sent back as a list
    back.put(([type(b).__name__ for b in batch], list(batch)))
