"""The scheduling a job's processes get, seen from outside (/proc), and what is said without
the privilege: cncd's log and status, `cncctl run`'s stderr and result."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from controller.motion.realtime import MOTION_PRIORITY, PRODUCER_NICE, probe_scheduling
from tests.daemon_helpers import CNCCTL, REPO, children_of, running_cncd, start_run

BUTTERFLY = REPO / "nc_programs" / "butterfly.nc"
NACA = str(REPO / "nc_programs" / "naca2415.nc")
SCHED_FIFO = 1


def _no_sys_nice() -> list[str]:
    """A prefix that runs a command without CAP_SYS_NICE (root's other powers kept): neither
    SCHED_FIFO (RLIMIT_RTPRIO is 0) nor a negative nice is permitted then."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to drop CAP_SYS_NICE")
    return ["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice"]


def _ordinary_nice() -> None:
    """Nice 0 for the child: an in-process `cncctl run` of an earlier test may have left this
    process at -10, which a child would inherit (and keep, privilege or not)."""
    os.setpriority(os.PRIO_PROCESS, 0, 0)


def _stat(pid: int, tid: int | None = None) -> list[str]:
    path = f"/proc/{pid}/task/{tid}/stat" if tid else f"/proc/{pid}/stat"
    return Path(path).read_text().rsplit(")", 1)[1].split()


def _nice(pid: int) -> int:
    return int(_stat(pid)[16])  # field 19 of stat: fields from the state on are 3..


def _fifo_threads(pid: int) -> list[tuple[str, int]]:
    """(name, rt priority) of the threads of pid under SCHED_FIFO."""
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            fields = _stat(pid, int(task.name))
            name = (task / "comm").read_text().strip()
        except OSError:
            continue
        if int(fields[38]) == SCHED_FIFO:  # policy (field 41), rt_priority (field 40)
            out.append((name, int(fields[37])))
    return out


def _producers_nice(daemon_pid: int, for_s: float = 1.5) -> dict[int, list[int]]:
    """The nice of each job process of the daemon (not multiprocessing's resource tracker),
    sampled every 20 ms."""
    seen: dict[int, list[int]] = {}
    deadline = time.monotonic() + for_s
    while time.monotonic() < deadline:
        for kid in children_of(daemon_pid):
            try:
                if b"resource_tracker" in Path(f"/proc/{kid}/cmdline").read_bytes():
                    continue
                seen.setdefault(kid, []).append(_nice(kid))
            except OSError:
                continue  # ended meanwhile
        time.sleep(0.02)
    return seen


def test_a_daemon_job_runs_as_reported(tmp_path: Path) -> None:
    """What the status and the result say is what /proc shows while the job runs."""
    expected = probe_scheduling()  # this process has the privileges the daemon has
    with running_cncd(tmp_path) as daemon:
        status = daemon.status()
        assert status["scheduling"]["privileged"] is expected.privileged
        assert daemon.cncctl("reset").returncode == 0
        run = start_run(daemon, BUTTERFLY)
        try:
            seen = _producers_nice(daemon.proc.pid)
            fifo = _fifo_threads(daemon.proc.pid)
            out, err = run.communicate(timeout=60)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait()
    final = json.loads(out.splitlines()[-1])
    assert run.returncode == 0, err
    sched = final["scheduling"]
    assert sched["privileged"] is expected.privileged
    # A child sampled right at its fork still has the daemon's nice: only those seen a while
    # count (the generator waits on the ring for seconds).
    nice = {values[-1] for values in seen.values() if len(values) >= 3}
    assert nice
    if expected.privileged:
        assert nice == {PRODUCER_NICE}
        assert sched["motion"] == f"SCHED_FIFO {MOTION_PRIORITY}"
        # the motion thread and the sim card's clock, opened at start-up
        assert len(fifo) >= 2 and {p for _, p in fifo} == {MOTION_PRIORITY}
    else:
        assert fifo == [] and nice == {0}


def test_without_privilege_cncd_says_so_at_start_and_in_status(tmp_path: Path) -> None:
    prefix = _no_sys_nice()
    with running_cncd(tmp_path, wrapper=prefix, preexec=_ordinary_nice) as daemon:
        sched = daemon.status()["scheduling"]
        assert sched["privileged"] is False and sched["motion"] == "SCHED_OTHER"
        assert sched["summary"].startswith("no privilege: ordinary scheduling")
        assert "scheduling: no privilege: ordinary scheduling" in daemon.log_text()
        text = daemon.cncctl("status").stdout
        assert "scheduling: no privilege: ordinary scheduling" in text


def test_without_privilege_cncctl_run_says_so_and_reports_it(tmp_path: Path) -> None:
    prefix = _no_sys_nice()
    done = subprocess.run([*prefix, *CNCCTL, "run", NACA, "--json"], capture_output=True,
                          text=True, timeout=120, cwd=REPO,  # no daemon: an embedded run
                          preexec_fn=_ordinary_nice)
    assert done.returncode == 0, done.stderr
    assert "cncctl: scheduling: no privilege: ordinary scheduling" in done.stderr
    sched = json.loads(done.stdout.splitlines()[-1])["scheduling"]
    assert sched == {**sched, "motion": "SCHED_OTHER", "producers": "nice 0",
                     "interpreter": "nice 0", "privileged": False}
