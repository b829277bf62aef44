"""`cncctl run PROG --from-line N` / `--home` embedded: home, approach where the program stands
at line N, then run it, all on one open drive (the daemon does the same in its job thread,
with the approach program made here)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from controller.config import MachineConfig
from controller.interpreter.program import position_at_line
from controller.motion.types import MotionResult, Outcome
from controller.offsets import OffsetTable
from controller.operator.daemon.check_process import check_in_child
from controller.operator.run.keys import enter_to_go
from controller.runtime.current_run import CurrentRun
from controller.runtime.processes import Runtime, RuntimeOptions, build_drive, open_drive
from drivers.base import Drive
from drivers.errors import HomingError
from drivers.homing import homing_groups

APPROACH_FEED_SHARE = 0.5  # of the maximum feed: a visible, interruptible move


def approach_program(config: MachineConfig, here_mm: tuple[float, float, float],
                     target_mm: tuple[float, float, float]) -> str:
    """G-code in machine coordinates (no offsets in force) for the approach: on a machine
    with Z, up to the higher of the two heights first, then across in XY, then down; on an XY
    table one straight move. Empty when the machine is already there (within a micrometre)."""
    feed = APPROACH_FEED_SHARE * config.interpolator.max_feed_mm_s * 60.0
    moves: list[str] = []
    x, y, z = target_mm
    if config.has_axis("z"):
        top = max(here_mm[2], z)
        if top - here_mm[2] > 1e-3:
            moves.append(f"G1 Z{top:.4f}")
        if max(abs(x - here_mm[0]), abs(y - here_mm[1])) > 1e-3:
            moves.append(f"G1 X{x:.4f} Y{y:.4f}")
        if top - z > 1e-3:
            moves.append(f"G1 Z{z:.4f}")
    elif max(abs(x - here_mm[0]), abs(y - here_mm[1])) > 1e-3:
        moves.append(f"G1 X{x:.4f} Y{y:.4f}")
    if not moves:
        return ""
    return f"G21 G90 G61 F{feed:.1f}\n" + "\n".join(moves) + "\nM2\n"


class HomingAborted(Exception):
    """The operator stopped the run (Ctrl-C, SIGTERM, SIGHUP) while the axes were homing."""


class Sequence(CurrentRun):
    """The runtime now running (approach, then program): operator requests go to it, and an
    abort asked before it (during the check, the homing or the question) is kept for it."""

    def __init__(self) -> None:
        super().__init__()
        self.drive: Drive | None = None  # open for the whole sequence: homing can be stopped

    def request_abort(self, message: str = "aborted by operator") -> None:
        self.abort = message  # before homing hears of it, as the current run does
        if self.drive is not None:
            self.drive.abort_homing(message)  # a no-op unless homing
        super().request_abort(message)


def confirm(args: argparse.Namespace, text: str,
            aborted: Callable[[], bool] = lambda: False) -> bool:
    """The operator confirms the approach (Enter), unless --yes. Ctrl-C, SIGTERM and SIGHUP
    cancel it: the run's own handlers only ask for an abort (aborted() tells, for one that
    came just before the question), which would leave the question waiting and, once
    answered, the approach moving."""
    print(text, file=sys.stderr, flush=True)
    return args.yes or enter_to_go("press Enter to move there, Ctrl-C to cancel", aborted)


def run_from_line(args: argparse.Namespace, config: MachineConfig, offsets: OffsetTable | None,
                  options: RuntimeOptions, seq: Sequence,
                  on_confirmed: Callable[[], None] = lambda: None) -> MotionResult | None:
    """On one open drive: homing first (--home), then the program, from line N after an
    approach (--from-line). None if the operator declined the approach (nothing moved);
    on_confirmed runs once it is confirmed (the keys are read from then on, not before: a
    reader of stdin would take the Enter the question waits for). An abort asked before a
    runtime starts is passed to it, which then stops at once: nothing more moves."""
    drive = build_drive(config, options.virtual_time)
    open_drive(drive)  # a drive that cannot be brought up: exit 2, nothing moved
    seq.drive = drive
    try:
        if getattr(args, "home", False):
            _home_all(drive, config, seq)
        start = drive.commanded_xyz_mm()
        if args.from_line is None:  # in a child: the drive's threads keep the interpreter
            check_in_child(args.program, config, offsets, start, None,  # lock (heartbeats)
                           lambda: False, lambda: None)
            return _run(seq, args.program, config, replace(
                options, drive=drive, keep_drive_open=True, start_mm=start))
        at = position_at_line(args.program, config, args.from_line, start, offsets)
        approach = approach_program(config, start, at.position_mm)
        where = " ".join(f"{n}{v:.3f}" for n, v in zip("XYZ", at.position_mm, strict=False))
        modes = f"{at.system} {at.distance_mode} F{at.feed_mm_s * 60:g}"
        question = (f"cncctl: run from line {args.from_line} ({modes}): a straight approach "
                    f"to machine {where} first")
        if seq.abort is None and not confirm(args, question, lambda: seq.abort is not None):
            return None
        on_confirmed()
        shared = replace(options, drive=drive, keep_drive_open=True)
        if approach:
            path = approach_file(approach)
            try:
                result = _run(seq, path, config, shared)
            finally:
                os.unlink(path)
            if result.outcome is not Outcome.DONE or seq.abort:
                return result
        return _run(seq, args.program, config, replace(shared, start_mm=start, offsets=offsets,
                                                       from_line=args.from_line))
    finally:
        seq.drive = None
        drive.close()


def _home_all(drive: Drive, config: MachineConfig, seq: Sequence) -> None:
    try:
        home_all(drive, config)
    except HomingError as exc:
        if seq.abort is not None:
            raise HomingAborted(f"{seq.abort} while homing: {exc}") from exc
        raise


def home_all(drive: Drive, config: MachineConfig) -> None:
    """Every axis with a homing sequence, group by group (drivers.homing)."""
    for group in homing_groups(config):
        names = ", ".join(config.axes[i].name.upper() for i in group)
        print(f"cncctl: homing {names}", file=sys.stderr, flush=True)
        drive.home(group)


def _run(seq: Sequence, path: str, config: MachineConfig, options: RuntimeOptions) -> Any:
    seq.current = Runtime(path, config, options)
    if seq.abort:
        seq.current.request_abort(seq.abort)
    return seq.current.run()


def approach_file(text: str) -> str:
    import tempfile
    with tempfile.NamedTemporaryFile("w", suffix=".nc", prefix="approach-", delete=False) as fh:
        fh.write(text)
    return fh.name
