"""cncd's reset after a lost drive link opens the drive again instead of failing until restart."""

from __future__ import annotations

from pathlib import Path

from controller.config import load_config
from controller.operator.daemon.log import EventLog
from controller.operator.daemon.machine import Machine, State
from drivers.sim.card import SimCard


def test_reset_after_a_lost_link_reopens_the_drive(tmp_path: Path) -> None:
    config = load_config("xy_table")
    card = SimCard(config, realtime=False)
    card.open()
    try:
        machine = Machine(config, card, tmp_path, EventLog(100), lambda topic, event: None)
        machine.reset()
        assert machine.state is State.IDLE
        card.inject_lost_comm()  # the link dies (the job, had one run, would have faulted)
        machine.reset()  # was: "drive reset failed: lost communication" until a restart
        assert machine.state is State.IDLE
        card.feedback()  # the link answers again
        assert "opening it again" in " ".join(e["message"] for e in machine.log.last(10))
    finally:
        card.close()
