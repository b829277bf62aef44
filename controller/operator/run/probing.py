"""`cncctl run` of a program with probes (G38), embedded: on one open drive with a probe input,
a stretch per probe (controller/runtime/probe_run.py)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from controller.config import MachineConfig
from controller.motion.types import MotionResult
from controller.offsets import OffsetTable
from controller.operator.check_cmd import refuse_probes
from controller.operator.daemon.check_process import check_in_child
from controller.runtime.probe_run import ProbeRun
from controller.runtime.processes import RuntimeOptions, build_drive, open_drive


def run_probing(args: argparse.Namespace, config: MachineConfig, offsets: OffsetTable | None,
                options: RuntimeOptions, seq: Any, lines: dict[int, str],
                on_event: Callable[[dict[str, Any]], None]) -> MotionResult:
    """Refused (NcError naming the first probe, nothing moved) on a drive without a probe
    input, and combined with --from-line or --home."""
    if args.from_line is not None or args.home:
        refuse_probes(args.program, lines, "--from-line and --home are not combined with "
                                           "probes yet")
    drive = build_drive(config, options.virtual_time)
    open_drive(drive)
    seq.drive = drive
    try:
        if drive.probe_input() is None:
            refuse_probes(args.program, lines, f"the {config.drive.backend} drive has no probe "
                          "input (drive option probe_workpiece_mm on the sim card, touch_probe "
                          "on canopen)")
        # checked again from where the drive stands, as every run on a kept-open drive is; in
        # a child, as cncd does: in this process the check held the interpreter lock for
        # seconds and the CANopen SYNC thread's heartbeats stopped (the drives faulted)
        check_in_child(args.program, config, offsets, drive.commanded_xyz_mm(), None,
                       lambda: False, lambda: None)
        run = ProbeRun(args.program, config, replace(options, offsets=offsets), drive, lines,
                       on_event)
        seq.current = run  # the keys' requests go to the stretch now running
        if seq.abort is not None:
            run.request_abort(seq.abort)
        return run.run()
    finally:
        drive.close()
