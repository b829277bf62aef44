"""When the run's processes collect garbage: Python's first-generation threshold raised where
nothing waits on a collection (the generator, the check, virtual time)."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

# Python's default is 700 net new container objects. The planner and the check make millions
# of short-lived objects and next to no reference cycles (a 30,000-line walk leaves some 100
# objects in cycles): at 700 the generator's collections were about 7 % of its CPU (0.3 s of
# a 30,000-line walk's, most of it re-scanning what it holds), at 10,000 a handful. Cycles
# are still collected, later; a real-time motion loop keeps the default (short collections).
GEN0_OBJECTS = 10_000


def collect_less() -> None:
    """From now on in this process (a producer, for its life): GEN0_OBJECTS."""
    gc.set_threshold(GEN0_OBJECTS, *gc.get_threshold()[1:])


@contextmanager
def fewer_collections() -> Iterator[None]:
    """GEN0_OBJECTS inside, the thresholds as they were after (also on an exception)."""
    before = gc.get_threshold()
    collect_less()
    try:
        yield
    finally:
        gc.set_threshold(*before)
