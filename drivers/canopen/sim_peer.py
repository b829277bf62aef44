"""`cncctl simdrive canopen`: the simulated drives in their own process behind a fake slcan pty."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable
from typing import Any

from controller.config import MachineConfig
from drivers.canopen.sim_drive import SimDriveSet
from drivers.canopen.slcan_pty import SlcanPty

SWITCH_INTERVAL_S = 0.0005  # this process only: hand the GIL over quickly (bus latency)
RT_PRIORITY = 70  # the drives stand in for hardware: below the motion process (80), best effort


def serve(config: MachineConfig, options: dict[str, Any], announce: Callable[[str], None],
          stop: threading.Event) -> None:
    """Drives on an in-process virtual bus, the pty adapter bridged to it; announce the pty
    path once both are up, serve until stop is set."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    with contextlib.suppress(AttributeError, OSError):  # before the threads: they inherit it
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    channel = f"cncsim-{os.getpid()}"
    drives = SimDriveSet(config, options, channel=channel)
    adapter = SlcanPty(channel)
    drives.host_pending = adapter.host_pending
    try:
        adapter.start()
        announce(adapter.path)
        while not stop.wait(0.2):
            pass
    finally:
        adapter.close()
        drives.close()
