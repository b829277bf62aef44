"""The reference ring as an anonymous shared mapping (no resource tracker process), a run's
interpreter stage reading the blocks its check kept instead of the program again, and the
children forked with the parent's objects frozen."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
from runtime_helpers import xy_config

from controller.interpreter.program import read_program
from controller.motion.ring import RefRing
from controller.motion.types import Outcome
from controller.operator.kept_blocks import KeptBlocks
from controller.runtime.processes import Runtime, RuntimeOptions
from controller.runtime.stages import BATCH_BLOCKS, GenerateFn, checked_blocks, reference_source

REPO = Path(__file__).resolve().parents[2]
CFG = xy_config()

_FORKED_RING = textwrap.dedent(
    """
    import multiprocessing.resource_tracker as tracker, os, sys
    import numpy as np
    from controller.motion.ring import FLAG_FINAL, RefRing
    ring = RefRing.create(16, 3)
    pid = os.fork()
    if pid == 0:  # the producer: what it writes, the parent reads
        ring.write(np.arange(30.0).reshape(10, 3))
        ring.set_flag(FLAG_FINAL)
        os._exit(0)
    os.waitpid(pid, 0)
    rows = ring.read(100)
    ring.close()
    print(len(rows), float(rows.sum()), tracker._resource_tracker._pid)
    """
)


def test_a_forked_producer_writes_into_the_ring_and_no_resource_tracker_starts() -> None:
    """In a fresh interpreter: a named SharedMemory started multiprocessing's resource
    tracker, a process of its own, for every run."""
    done = subprocess.run(
        [sys.executable, "-c", _FORKED_RING],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        check=True,
    )
    n_rows, total, tracker_pid = done.stdout.split()
    assert (int(n_rows), float(total)) == (10, sum(range(30)))
    assert tracker_pid == "None"


def test_the_interpreter_stage_runs_the_blocks_the_check_kept(tmp_path: Path) -> None:
    """The stage reads the kept blocks, not the path (which is gone by then), and passes them
    on in batches (more blocks than one): the same run. The check keeps lines past its first
    ones as numbers (`cncctl run` keeps them so): the blocks made again run the same."""
    program = tmp_path / "squares.nc"
    squares = "G1 X0.5\nG1 Y0.5\nG1 X0\nG1 Y0\n" * (BATCH_BLOCKS // 4 + 8)
    program.write_text(f"G21 G90 G64 F3000\n{squares}M2\n")
    kept = KeptBlocks(max_blocks=100, max_lines=10_000, lines_as_blocks=10)
    for block in read_program(str(program), CFG):
        kept.append(block)
    assert len(kept) > BATCH_BLOCKS and not kept.full
    whole = Runtime(str(program), CFG, RuntimeOptions(virtual_time=True)).run()
    program.unlink()
    options = RuntimeOptions(virtual_time=True, blocks_fn=checked_blocks(kept))
    checked = Runtime(str(program), CFG, options).run()
    assert whole.outcome is checked.outcome is Outcome.DONE
    assert checked.motion_time_s == whole.motion_time_s > 0.0
    assert checked.final_position_mm == whole.final_position_mm
    # Both ran the three processes: the interpreter passed on the blocks it inherited.
    assert set(whole.extra["peak_rss_mb"]) == {"interpreter", "generator", "motion"}
    assert set(checked.extra["peak_rss_mb"]) == {"interpreter", "generator", "motion"}


def _frozen_in_child(out: Path) -> GenerateFn:
    def generate(blocks: Any, config: Any) -> Any:
        out.write_text(str(gc.get_freeze_count()))
        yield from reference_source(blocks, config)

    return generate


def test_the_children_start_with_the_parents_objects_frozen(tmp_path: Path) -> None:
    """Frozen at the fork, the objects the parent holds are not scanned by a child's
    collections (nor their pages copied by them); the parent's are unfrozen again."""
    program = tmp_path / "line.nc"
    program.write_text("G21 G90 F600\nG1 X1\nM2\n")
    seen = tmp_path / "frozen"
    options = RuntimeOptions(virtual_time=True, generate_fn=_frozen_in_child(seen))
    assert Runtime(str(program), CFG, options).run().outcome is Outcome.DONE
    assert int(seen.read_text()) > 1000
    assert gc.get_freeze_count() == 0


def test_rows_written_and_read_across_the_rings_end_come_back_in_order() -> None:
    """Writes and reads of any size, wrapping round a 7-row ring many times (copied as two
    slices where they cross its end)."""
    ring = RefRing.create(7, 3)
    rng = np.random.default_rng(0)
    rows = rng.normal(size=(500, 3))
    out, written = [], 0
    try:
        while written < len(rows) or ring.available():
            room = min(7 - ring.available(), len(rows) - written)
            if room:
                n = int(rng.integers(1, room + 1))
                assert ring.write(rows[written : written + n])
                written += n
            out.append(ring.read(int(rng.integers(0, 9))))
    finally:
        ring.close()
    assert np.array_equal(np.concatenate(out), rows)
