"""`cncctl run PROG --from-line N` / `--home` embedded: home, approach where the program stands
at line N, then run it, all on one open drive (the daemon does the same in its job thread)."""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from typing import Any

from controller.config import MachineConfig
from controller.interpreter.program import position_at_line
from controller.motion.types import MotionResult, Outcome
from controller.offsets import OffsetTable
from controller.operator.check_cmd import check_program
from controller.operator.from_line import approach_program
from controller.runtime.processes import Runtime, RuntimeOptions, build_drive, open_drive
from drivers.base import Drive
from drivers.homing import homing_groups


class Sequence:
    """The runtime now running (approach, then program): operator requests go to it."""

    def __init__(self) -> None:
        self.current: Runtime | None = None
        self.abort: str | None = None

    def request_hold(self) -> None:
        if self.current is not None:
            self.current.request_hold()

    def request_resume(self) -> None:
        if self.current is not None:
            self.current.request_resume()

    def set_feed_override(self, percent: float) -> None:
        if self.current is not None:
            self.current.set_feed_override(percent)

    def request_abort(self, message: str) -> None:
        self.abort = message
        if self.current is not None:
            self.current.request_abort(message)


def confirm(args: argparse.Namespace, text: str) -> bool:
    """The operator confirms the approach (Enter), unless --yes."""
    print(text, file=sys.stderr, flush=True)
    if args.yes:
        return True
    print("press Enter to move there, Ctrl-C to cancel", file=sys.stderr, flush=True)
    try:
        return sys.stdin.readline() != ""
    except (KeyboardInterrupt, OSError):
        return False


def run_from_line(args: argparse.Namespace, config: MachineConfig, offsets: OffsetTable | None,
                  options: RuntimeOptions, seq: Sequence) -> MotionResult | None:
    """On one open drive: homing first (--home), then the program, from line N after an
    approach (--from-line). None if the operator declined the approach (nothing moved)."""
    drive = build_drive(config, options.virtual_time)
    open_drive(drive)  # a drive that cannot be brought up: exit 2, nothing moved
    try:
        if getattr(args, "home", False):
            home_all(drive, config)
        start = drive.commanded_xyz_mm()
        if args.from_line is None:
            check_program(args.program, config, start_mm=start, offsets=offsets,
                          summary=False)
            return _run(seq, args.program, config, replace(
                options, drive=drive, keep_drive_open=True, start_mm=start))
        at = position_at_line(args.program, config, args.from_line, start, offsets)
        approach = approach_program(config, start, at.position_mm)
        where = " ".join(f"{n}{v:.3f}" for n, v in zip("XYZ", at.position_mm, strict=False))
        modes = f"{at.system} {at.distance_mode} F{at.feed_mm_s * 60:g}"
        if not confirm(args, f"cncctl: run from line {args.from_line} ({modes}): a straight "
                             f"approach to machine {where} first"):
            return None
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
        drive.close()


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
