"""An idle cncd costs about no CPU: measured from outside, on its own process's CPU time."""

from __future__ import annotations

import os
import time
from pathlib import Path

from tests.daemon_helpers import REPO, running_cncd

IDLE_LIMIT = 0.02  # of one core
MEASURE_S = 4.0
SETTLE_S = 3.0  # the sim card's clock sleeps once the table has been at rest 2 s


def _cpu_s(pid: int) -> float:
    """User + system CPU of every thread of the process so far (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _idle_share(pid: int) -> float:
    # CPU time, not wall time, is what is asserted: a loaded machine gives a polling loop less
    # CPU, never more, so the bound holds whatever else runs.
    time.sleep(SETTLE_S)
    before_s, t0_s = _cpu_s(pid), time.monotonic()
    time.sleep(MEASURE_S)
    return (_cpu_s(pid) - before_s) / (time.monotonic() - t0_s)


def test_idle_daemon_uses_under_two_percent_of_a_core(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as daemon:
        share = _idle_share(daemon.proc.pid)
        assert share < IDLE_LIMIT, f"idle cncd in ESTOP used {share:.1%} of a core"
        assert daemon.cncctl("reset").returncode == 0
        share = _idle_share(daemon.proc.pid)
        assert share < IDLE_LIMIT, f"idle cncd after reset used {share:.1%} of a core"


def test_daemon_idle_again_after_a_job(tmp_path: Path) -> None:
    """A job wakes the simulated card's clock; once the table is at rest it sleeps again."""
    with running_cncd(tmp_path) as daemon:
        assert daemon.cncctl("reset").returncode == 0
        done = daemon.cncctl("run", str(REPO / "nc_programs" / "naca2415.nc"), "--json")
        assert done.returncode == 0, done.stderr
        share = _idle_share(daemon.proc.pid)
        assert share < IDLE_LIMIT, f"cncd idle after a job used {share:.1%} of a core"
