"""Scheduling of a job's processes: SCHED_FIFO for the motion thread and the drive's threads,
a negative nice for the interpreter and generator; what is permitted, probed and reported."""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

MOTION_PRIORITY = 80  # SCHED_FIFO of the motion thread and the drive's threads (LimitRTPRIO=90)
PRODUCER_NICE = -10  # interpreter and generator outrank ordinary load (nice 0), not the motion
ORDINARY = "SCHED_OTHER"
# How long a thread that wants the GIL waits before the holder is asked to let go. Python's
# 5 ms is longer than a motion cycle (2 ms): the control socket's thread serving a flood of
# clients held the motion thread up past its cycle (21 late cycles in the butterfly).
GIL_SWITCH_S = 0.0002
NEEDS = (f"root, CAP_SYS_NICE, or LimitRTPRIO>={MOTION_PRIORITY} and LimitNICE={PRODUCER_NICE}"
         " (systemd/cncd.service)")


def try_realtime(priority: int) -> str:
    """Raise the calling thread to SCHED_FIFO; returns the policy achieved.

    Call it after forking the producer processes (they get their own nice, see producer_nice)
    and before starting the card thread (which inherits the policy). No mlockall: locking every
    mapped page of numpy/scipy took ~0.3 s and ~300 MB, against the 0.5 s time-to-first-motion
    target. Failure is not an error: without CAP_SYS_NICE / LimitRTPRIO the card FIFO still
    absorbs late wake-ups, they are only more frequent.
    """
    share_the_gil_often()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return f"SCHED_FIFO {priority}"
    except (PermissionError, OSError, AttributeError):
        return ORDINARY


def share_the_gil_often() -> None:
    """A process with a motion thread hands the GIL over within GIL_SWITCH_S (process-wide;
    the other threads then run in slices of that length, which costs little)."""
    sys.setswitchinterval(min(sys.getswitchinterval(), GIL_SWITCH_S))


def back_to_normal() -> None:
    """Undo SCHED_FIFO (after the run, before UI work or joining children)."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (PermissionError, OSError, AttributeError):
        pass


def producer_nice() -> str:
    """Set the calling thread's nice to PRODUCER_NICE (absolute: a parent already at -10 does
    not make it -20); returns what it runs at, e.g. "nice -10", "nice 0" where refused."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, PRODUCER_NICE)
    except OSError:
        pass  # no CAP_SYS_NICE and no LimitNICE: it keeps the nice it had
    return f"nice {os.getpriority(os.PRIO_PROCESS, 0)}"


def service_nice() -> str:
    """The daemon's socket threads at the producers' nice: a flood of clients (ordinary
    processes at nice 0) then cannot outrun the loop that turns them away, which kept the
    listen queue full and status requests waiting seconds behind it."""
    return producer_nice()


@contextmanager
def realtime_threads(priority: int = MOTION_PRIORITY) -> Iterator[str]:
    """Threads started inside (a drive's card clock, SYNC or reader thread, started by open())
    inherit SCHED_FIFO, as in `cncctl run`, where the drive is opened from the motion thread;
    the calling thread itself is back to SCHED_OTHER after it."""
    policy = try_realtime(priority)
    try:
        yield policy
    finally:
        if policy != ORDINARY:
            back_to_normal()


@dataclass(frozen=True)
class Scheduling:
    """What a job's processes run at: the motion thread (and the drive's threads) and the
    producers (interpreter and generator)."""

    motion: str
    producers: str

    @property
    def privileged(self) -> bool:
        return self.motion != ORDINARY and self.producers == f"nice {PRODUCER_NICE}"

    def summary(self) -> str:
        if self.privileged:
            return (f"real time: motion and drive {self.motion}, interpreter and generator "
                    f"{self.producers}")
        kind = ("no privilege: ordinary scheduling" if self.motion == ORDINARY
                else "partly privileged")
        return (f"{kind} (motion and drive {self.motion}, interpreter and generator "
                f"{self.producers}): late cycles are likelier under load; needs {NEEDS}")

    def as_dict(self) -> dict[str, Any]:
        return {"motion": self.motion, "producers": self.producers,
                "privileged": self.privileged, "summary": self.summary()}


def probe_scheduling(priority: int = MOTION_PRIORITY) -> Scheduling:
    """What this process may get, tried in a thread of its own that ends at once (on Linux both
    the policy and the nice are per thread): nothing else in the process changes."""
    got: dict[str, str] = {}

    def probe() -> None:
        got["motion"] = try_realtime(priority)
        got["producers"] = producer_nice()

    thread = threading.Thread(target=probe, name="sched-probe", daemon=True)
    thread.start()
    thread.join()
    return Scheduling(got.get("motion", ORDINARY), got.get("producers", "nice 0"))
