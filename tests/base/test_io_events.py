"""One shape for every event line: the motion loop's output events and the run's tool and probe
events are built by the same function."""

from __future__ import annotations

import pytest

from controller.io_events import io_event
from controller.motion.events import JobEvents


def test_the_motion_loops_events_are_the_io_events_shape() -> None:
    seen: list[dict] = []
    job = JobEvents(seen.append)
    out = job.emit("output", 1.0000004, 3, name="digital_0", value=True)
    assert out == io_event("output", 1.0000004, 3, name="digital_0", value=True) == seen[0]
    assert list(out) == ["event", "t_s", "line", "name", "value"] and out["t_s"] == 1.0
    probe = io_event("probe", 2.1234567, 7, code="G38.2")
    assert list(probe)[:3] == ["event", "t_s", "line"] and probe["t_s"] == 2.123457


def test_an_unknown_kind_is_refused_by_either() -> None:
    with pytest.raises(ValueError, match="unknown I/O event 'spindle'"):
        JobEvents().emit("spindle", 0.0, 1)
