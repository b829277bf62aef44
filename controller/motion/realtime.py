"""Best-effort real-time scheduling for the motion process (SCHED_FIFO), undone after the run."""

from __future__ import annotations

import os


def try_realtime(priority: int) -> str:
    """Raise the calling process to SCHED_FIFO; returns the policy achieved.

    Call it after forking the producer processes (they stay SCHED_OTHER) and before starting
    the card thread (which inherits the policy). No mlockall: locking every mapped page of
    numpy/scipy took ~0.3 s and ~300 MB, against the 0.5 s time-to-first-motion target.
    Failure is not an error: without CAP_SYS_NICE / LimitRTPRIO the card FIFO still absorbs
    late wake-ups, they are only more frequent.
    """
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return f"SCHED_FIFO {priority}"
    except (PermissionError, OSError, AttributeError):
        return "SCHED_OTHER"


def back_to_normal() -> None:
    """Undo SCHED_FIFO (after the run, before UI work or joining children)."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (PermissionError, OSError, AttributeError):
        pass
