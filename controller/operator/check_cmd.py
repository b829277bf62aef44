"""`cncctl check PROGRAM`: parse a whole program, check travel limits, print a summary."""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Literal, overload

from controller.blocks import ArcBlock, HelixBlock, LineBlock, NurbsBlock, ProbeBlock
from controller.config import CONFIG_HELP, MachineConfig, load_config
from controller.errors import ConfigError, DriveError, NcError, OffsetsError
from controller.interpreter.extent import (
    TravelLimits,
    arc_length_and_box,
    helix_length_and_box,
    line_length_and_box,
    nurbs_hull_box,
    nurbs_length_and_box,
)
from controller.interpreter.program import read_program
from controller.offsets import OffsetTable, ProgramOffsets, load_offsets
from controller.operator.drive_args import (
    add_drive_option_argument,
    config_with_drive_options,
    probe_drive,
)
from controller.operator.kept_blocks import KeptBlocks
from controller.tools import ToolTableError, load_tool_table

_AXES = ("x", "y", "z")


@dataclass
class CheckSummary:
    """What `check` found: counts, lengths, the box the tool moves in and the machine travel."""

    program: str
    config: str
    blocks: dict[str, int] = field(default_factory=dict)
    path_length_mm: float = 0.0
    feed_length_mm: float = 0.0
    rapid_length_mm: float = 0.0
    nominal_time_s: float = 0.0  # length / programmed feed, no acceleration: a lower bound
    nurbs_blocks: int = 0
    nurbs_control_points: int = 0
    extents_mm: dict[str, list[float]] = field(default_factory=dict)
    travel_mm: dict[str, list[float]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # accepted where LinuxCNC refuses


_GEOMETRY = {LineBlock: line_length_and_box, ArcBlock: arc_length_and_box,
             HelixBlock: helix_length_and_box,
             NurbsBlock: nurbs_length_and_box,
             ProbeBlock: line_length_and_box}
# NURBS: from dense samples, 64 per knot span; G38: the whole move, the farthest it can go

CHECK_BEAT_BLOCKS = 4096  # on_block is called every this many blocks
# A check keeps up to this many blocks for its caller (simulate plans them without reading the
# program again), some 10 MB, and up to KEEP_LINES G0/G1 lines, those past the first
# KEEP_BLOCKS as numbers (32 MB); a longer program is read twice, in bounded memory.
KEEP_BLOCKS = 30_000
KEEP_LINES = 1_000_000


@overload
def check_program(path: str, config: MachineConfig,
                  on_block: Callable[[int], None] | None = None,
                  start_mm: tuple[float, float, float] | None = None,
                  offsets: OffsetTable | None = None, from_line: int | None = None,
                  track: ProgramOffsets | None = None, summary: Literal[True] = True,
                  keep: KeptBlocks | None = None) -> CheckSummary: ...


@overload
def check_program(path: str, config: MachineConfig,
                  on_block: Callable[[int], None] | None = None,
                  start_mm: tuple[float, float, float] | None = None,
                  offsets: OffsetTable | None = None, from_line: int | None = None,
                  track: ProgramOffsets | None = None, *, summary: Literal[False],
                  keep: KeptBlocks | None = None) -> None: ...


def check_program(path: str, config: MachineConfig,
                  on_block: Callable[[int], None] | None = None,
                  start_mm: tuple[float, float, float] | None = None,
                  offsets: OffsetTable | None = None, from_line: int | None = None,
                  track: ProgramOffsets | None = None, summary: bool = True,
                  keep: KeptBlocks | None = None) -> CheckSummary | None:
    """Parse and check the whole program (from from_line, if given) with the work offsets in
    force; raise NcError at the first problem, travel in machine coordinates. on_block(n), if
    given, is called every CHECK_BEAT_BLOCKS blocks (the daemon's watchdog sees the check
    alive on a program of millions of lines); track.table is the offset table it leaves.

    summary=False (a check before motion, nothing printed): the same errors, but a NURBS whose
    control points lie inside the travel is not sampled for its length and extent (it lies in
    their hull), which was a tenth of simulating a program of distinct NURBS; returns None.

    keep: the blocks are appended to it until it is full (then the caller reads the program
    again rather than hold a long one), so that a short one is not read twice."""
    kinds: Counter[type] = Counter()
    start = start_mm if start_mm is not None else (0.0, 0.0, 0.0)
    lo, hi = list(start), list(start)  # where the machine stands (X0 Y0 Z0 by default)
    feed_mm = rapid_mm = time_s = 0.0
    nurbs_points = 0
    n = 0
    track = track if track is not None else ProgramOffsets()
    travel = TravelLimits(config)
    limits = travel.axes  # (index, axis, min, max) of each axis the machine has
    for block in read_program(path, config, start_mm, offsets, from_line, track):
        n += 1
        if keep is not None:
            keep.append(block)
        if on_block is not None and n % CHECK_BEAT_BLOCKS == 0:
            on_block(n)
        kind = type(block)
        kinds[kind] += 1
        geometry = _GEOMETRY.get(kind)
        if geometry is None:
            continue
        if not summary and kind is NurbsBlock and travel.holds(nurbs_hull_box(block)):
            continue
        length, (blo, bhi) = geometry(block)
        travel.check(path, block, (blo, bhi), track.table)
        if not summary:
            continue
        for i, _, _, _ in limits:
            if blo[i] < lo[i]:
                lo[i] = blo[i]
            if bhi[i] > hi[i]:
                hi[i] = bhi[i]
        time_s += length / block.feed_mm_s  # type: ignore[union-attr]
        if kind is LineBlock and block.rapid:  # type: ignore[union-attr]
            rapid_mm += length
        else:
            feed_mm += length
        if kind is NurbsBlock:
            nurbs_points += block.control_points.shape[0]  # type: ignore[union-attr]
    if not summary:
        return None
    return CheckSummary(
        program=path, config=config.name,
        blocks=dict(sorted((k.__name__, v) for k, v in kinds.items())),
        path_length_mm=feed_mm + rapid_mm, feed_length_mm=feed_mm, rapid_length_mm=rapid_mm,
        nominal_time_s=time_s, nurbs_blocks=kinds[NurbsBlock], nurbs_control_points=nurbs_points,
        extents_mm={name: [lo[i], hi[i]] for i, name, _, _ in limits},
        travel_mm={name: [tlo, thi] for _, name, tlo, thi in limits},
        warnings=list(track.warnings))


def refuse_probes(path: str, seen: dict[int, str], why: str) -> None:
    """A run that cannot probe (through cncd, a drive without a probe input, run from line):
    an NcError naming the first probe, before any motion."""
    if seen:
        line = min(seen)
        raise NcError(path, line, 1, seen[line], f"{seen[line]}: probing is checked (`cncctl "
                      f"check`) but cannot run here: {why}; nothing moved")


def _json_error(args: argparse.Namespace, kind: str, message: str) -> None:
    """--json: every outcome is one JSON object on stdout (a program error has file and line,
    a config or drive error only its kind and message)."""
    if args.json:
        print(json.dumps({"ok": False, "error": {"kind": kind, "message": message}}))


def format_summary(s: CheckSummary) -> str:
    lines = [f"{s.program}: OK (config {s.config})",
             "blocks: " + (", ".join(f"{k} {v}" for k, v in s.blocks.items()) or "none"),
             f"path length: {s.path_length_mm:.3f} mm (feed {s.feed_length_mm:.3f} mm, "
             f"rapid {s.rapid_length_mm:.3f} mm)",
             f"nominal time at programmed feed: {s.nominal_time_s:.3f} s",
             f"NURBS: {s.nurbs_blocks} blocks, {s.nurbs_control_points} control points"]
    for name, (lo, hi) in s.extents_mm.items():
        tlo, thi = s.travel_mm[name]
        lines.append(f"{name.upper()}: {lo:.4f} .. {hi:.4f} mm (travel {tlo:g} .. {thi:g})")
    lines += [f"warning: {w}" for w in s.warnings]
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("program", help="G-code program file")
    parser.add_argument("--config", help=CONFIG_HELP)
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--offsets", metavar="FILE",
                        help="work offset table (JSON, as cncd keeps it in its state "
                             "directory) in force for the check")
    parser.add_argument("--tools", metavar="TBL", help="tool table (LinuxCNC tool.tbl) in "
                        "force, in place of the config's tools.table_file")
    add_drive_option_argument(parser)


def run(args: argparse.Namespace) -> int:
    try:
        config = config_with_drive_options(load_config(args.config), args.drive_option)
        offsets = load_offsets(args.offsets, missing_ok=False) \
            if args.offsets is not None else None
        if args.tools is not None:
            config = replace(config, tools=config.tools.with_table(
                load_tool_table(args.tools, missing_ok=False)))
        summary = check_program(args.program, config, offsets=offsets)
        assert summary is not None  # summary=True
        probe_drive(config)
    except (ConfigError, OffsetsError, ToolTableError) as exc:
        print(f"cncctl: config error: {exc}", file=sys.stderr)
        _json_error(args, "config", str(exc))
        return 2
    except DriveError as exc:
        print(f"cncctl: drive {config.drive.backend!r} cannot be opened: {exc}", file=sys.stderr)
        _json_error(args, "drive", str(exc))
        return 2
    except NcError as exc:
        print(exc.format(), file=sys.stderr)
        if args.json:
            print(json.dumps({"ok": False, "error": {
                "program": exc.path, "line": exc.line, "col": exc.col, "word": exc.word,
                "message": exc.message}}))
        return 2
    if args.json:
        print(json.dumps({"ok": True, **asdict(summary)}, indent=2))
    else:
        print(format_summary(summary))
    return 0
