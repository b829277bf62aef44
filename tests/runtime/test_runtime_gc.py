"""Collections of a run: the generator's first generation collected at GEN0_OBJECTS, the
motion process's objects from before the run frozen while it runs and unfrozen after."""

from __future__ import annotations

import gc
from pathlib import Path
from typing import Any

import pytest
from runtime_helpers import xy_config

from controller.motion.types import Outcome
from controller.runtime.gc_policy import GEN0_OBJECTS, fewer_collections
from controller.runtime.processes import Runtime, RuntimeOptions
from controller.runtime.stages import GenerateFn, reference_source

CFG = xy_config()


def _threshold_in_child(out: Path) -> GenerateFn:
    def generate(blocks: Any, config: Any) -> Any:
        out.write_text(" ".join(map(str, gc.get_threshold())))
        yield from reference_source(blocks, config)

    return generate


def test_the_generator_collects_its_first_generation_less_often(tmp_path: Path) -> None:
    program = tmp_path / "line.nc"
    program.write_text("G21 G90 F600\nG1 X1\nM2\n")
    seen = tmp_path / "threshold"
    before = gc.get_threshold()
    options = RuntimeOptions(virtual_time=True, generate_fn=_threshold_in_child(seen))
    assert Runtime(str(program), CFG, options).run().outcome is Outcome.DONE
    gen0, *older = map(int, seen.read_text().split())
    assert gen0 == GEN0_OBJECTS > before[0]
    assert tuple(older) == before[1:]
    assert gc.get_threshold() == before  # this process's own are as they were


def test_the_motion_process_runs_with_its_objects_frozen_and_unfreezes_them(
    tmp_path: Path,
) -> None:
    program = tmp_path / "line.nc"
    program.write_text("G21 G90 F600\nG1 X5\nM2\n")
    frozen: list[tuple[int, int]] = []
    options = RuntimeOptions(
        virtual_time=True,
        on_progress=lambda p: frozen.append((gc.get_freeze_count(), gc.get_threshold()[0])),
    )
    before = gc.get_threshold()
    assert gc.get_freeze_count() == 0
    assert Runtime(str(program), CFG, options).run().outcome is Outcome.DONE
    assert frozen and min(n for n, _ in frozen) > 1000
    # In virtual time no cycle waits on a collection: fewer of them while it runs.
    assert {gen0 for _, gen0 in frozen} == {GEN0_OBJECTS}
    assert gc.get_freeze_count() == 0
    assert gc.get_threshold() == before


def test_fewer_collections_puts_the_thresholds_back_after_an_exception() -> None:
    before = gc.get_threshold()
    with pytest.raises(RuntimeError), fewer_collections():
        assert gc.get_threshold() == (GEN0_OBJECTS, *before[1:])
        raise RuntimeError
    assert gc.get_threshold() == before


def test_a_run_that_cannot_open_its_drive_unfreezes_too(tmp_path: Path) -> None:
    program = tmp_path / "line.nc"
    program.write_text("G21 G90 F600\nG1 X5\nM2\n")

    class NoDrive:
        config = CFG

        def open(self) -> None:
            raise OSError("no such card")

        def close(self) -> None:
            pass

    options = RuntimeOptions(virtual_time=True, drive=NoDrive())  # type: ignore[arg-type]
    with pytest.raises(OSError, match="no such card"):
        Runtime(str(program), CFG, options).run()
    assert gc.get_freeze_count() == 0
