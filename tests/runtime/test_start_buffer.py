"""A job starts moving only once the reference buffer is full or the program is planned to its
end (runtime.reference_buffer_s): a slow generator's head start is the whole buffer."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
import refgen

from controller.motion.types import Outcome
from controller.refpoints import RefChunk
from controller.runtime.processes import Runtime, RuntimeOptions
from drivers.sim.card import SimCard
from tests.runtime.test_runtime_faults import CFG

CHUNK_ROWS = 50
CHUNK_WAIT_S = 0.01  # the generator's time per chunk: 50 ms of motion in 10 ms


def _slow(radius_mm: float) -> object:
    def generate(blocks: object, config: object) -> Iterator[RefChunk]:
        list(blocks)  # type: ignore[call-overload]
        for chunk in refgen.circle_chunks(radius_mm=radius_mm, size=CHUNK_ROWS):
            time.sleep(CHUNK_WAIT_S)
            yield chunk
    return generate


@pytest.mark.parametrize(("radius_mm", "ring_s", "rows_before_motion"), [
    (20.0, 1.0, 1000),  # 2.2 s of circle: motion once the 1 s ring is full
    (10.0, 5.0, 1100),  # 1.1 s of circle in a 5 s ring: motion once it is all planned
])
def test_first_motion_waits_for_a_full_buffer_or_the_end(radius_mm: float, ring_s: float,
                                                         rows_before_motion: int) -> None:
    opts = RuntimeOptions(blocks_fn=refgen.fake_blocks, generate_fn=_slow(radius_mm),
                          drive=SimCard(CFG, realtime=True), ring_seconds=ring_s)
    result = Runtime("test.nc", CFG, opts).run()
    assert result.outcome is Outcome.DONE, result.message
    # The generator cannot have written those rows sooner than its sleeps allow; before, the
    # motion began after about 110 rows (holdback and low water), 20 ms into the stream.
    at_least_s = (rows_before_motion // CHUNK_ROWS) * CHUNK_WAIT_S
    assert result.time_to_first_motion_s is not None
    assert result.time_to_first_motion_s >= at_least_s
