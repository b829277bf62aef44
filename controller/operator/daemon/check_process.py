"""cncd's program check in a child process: the daemon stays responsive and can end it at once.

In the daemon's own job thread the check held the interpreter lock: a 60 MB comment-only
program withheld the watchdog for 4 s, and an abort answered ok while the job stayed CHECKING
for 21 s (the check looked at nothing until its end). Here the check runs in a forked child
(as the interpreter and generator do); the job thread waits on a pipe, beats the watchdog
while the child lives, and kills it within CHECK_POLL_S of an abort, an e-stop or SIGTERM.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from controller.config import MachineConfig
from controller.errors import CncError, NcError
from controller.interpreter.program import position_at_line
from controller.offsets import OffsetTable, ProgramOffsets
from controller.operator.check_cmd import check_program, refuse_probes
from controller.runtime.stages import memory_ceiling

CHECK_POLL_S = 0.02  # how often the job thread looks at its cancel flag while the child checks
_CTX = mp.get_context("fork")


class CheckCancelled(CncError):
    """The check was ended by an abort, an e-stop or SIGTERM: nothing moved."""


@dataclass
class CheckOutcome:
    approach_mm: tuple[float, float, float] | None = None
    table: OffsetTable = field(default_factory=OffsetTable)
    override_off_lines: list[list[int]] = field(default_factory=list)
    io_events: list[dict[str, Any]] = field(default_factory=list)  # tool changes (M6)
    probe_lines: dict[int, str] = field(default_factory=dict)  # G38 lines: line -> code


def check_in_child(path: str, config: MachineConfig, offsets: OffsetTable | None,
                   start_mm: tuple[float, float, float], from_line: int | None,
                   cancelled: Callable[[], bool], beat: Callable[[], None]) -> CheckOutcome:
    """What check_program (and, from a line, position_at_line) find, computed in a child;
    NcError as the child raised it; CheckCancelled once cancelled() says so."""
    receive, send = _CTX.Pipe(duplex=False)
    child = _CTX.Process(target=_child, args=(send, path, config, offsets, start_mm, from_line,
                                              os.getpid()), name="cncd-check", daemon=True)
    child.start()
    send.close()
    try:
        while not receive.poll(CHECK_POLL_S):
            beat()
            if cancelled():
                raise CheckCancelled("the check was ended")
            if not child.is_alive() and not receive.poll(0):
                raise CncError(f"the program check ended without an answer (exit code "
                               f"{child.exitcode})")
        try:
            kind, payload = receive.recv()
        except EOFError:
            raise CncError("the program check ended without an answer") from None
    finally:
        receive.close()
        if child.is_alive():
            child.kill()
        child.join(timeout=5.0)
    if kind == "nc":
        raise NcError(*payload)
    if kind == "error":
        raise CncError(f"the program check failed: {payload}")
    return payload


def _child(send: Any, path: str, config: MachineConfig, offsets: OffsetTable | None,
           start_mm: tuple[float, float, float], from_line: int | None, parent_pid: int) -> None:
    from controller.runtime.stages import _die_with_parent

    _die_with_parent(parent_pid)
    memory_ceiling()
    try:
        outcome = CheckOutcome()
        if from_line is not None:  # lines before it are read from where the machine stands
            outcome.approach_mm = position_at_line(path, config, from_line, start_mm,
                                                   offsets).position_mm
        track = ProgramOffsets()
        check_program(path, config, offsets=offsets, start_mm=start_mm, from_line=from_line,
                      track=track, summary=False)
        if from_line is not None:
            refuse_probes(path, track.probes.seen, "run from line is not combined with "
                                                   "probes yet")
        outcome.probe_lines = track.probes.seen
        outcome.table, outcome.override_off_lines = track.table, track.override_off_lines
        outcome.io_events = track.io_events
        send.send(("ok", outcome))
    except NcError as exc:
        send.send(("nc", (exc.path, exc.line, exc.col, exc.word, exc.message)))
    except Exception as exc:  # noqa: BLE001  (reported to the daemon, which faults the job)
        send.send(("error", f"{type(exc).__name__}: {str(exc)[:300]}"))
    finally:
        send.close()
