"""`cncctl check PROGRAM`: parse a whole program, check travel limits, print a summary."""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from dataclasses import asdict, dataclass, field

from controller.blocks import ArcBlock, LineBlock, NcBlock, NurbsBlock
from controller.config import MachineConfig, load_config
from controller.errors import ConfigError, NcError
from controller.interpreter import read_program
from controller.nc_geometry import Box, arc_block_box, line_box, nurbs_length_and_box

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


def _block_geometry(block: NcBlock) -> tuple[float, Box | None]:
    """Length and box of a motion block (NURBS: from dense samples, 64 per knot span)."""
    if isinstance(block, LineBlock):
        return block.length_mm, line_box(block)
    if isinstance(block, ArcBlock):
        return block.length_mm, arc_block_box(block)
    if isinstance(block, NurbsBlock):
        return nurbs_length_and_box(block)
    return 0.0, None


Problem = tuple[str, float, tuple[float, float]]


def _limit_problem(box: Box, config: MachineConfig) -> Problem | None:
    """(axis, position reached, travel) of the first axis whose travel the box leaves."""
    for i, name in enumerate(_AXES):
        if not config.has_axis(name):
            continue
        lo, hi = config.axis(name).travel_mm
        if box[0][i] < lo:
            return name, box[0][i], (lo, hi)
        if box[1][i] > hi:
            return name, box[1][i], (lo, hi)
    return None


def check_program(path: str, config: MachineConfig) -> CheckSummary:
    """Parse and check the whole program; raise NcError at the first problem."""
    summary = CheckSummary(program=path, config=config.name)
    kinds: Counter[str] = Counter()
    lo, hi = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]  # the machine starts at X0 Y0 Z0
    for block in read_program(path, config):
        kinds[type(block).__name__] += 1
        length, box = _block_geometry(block)
        if box is None:
            continue
        problem = _limit_problem(box, config)
        if problem is not None:
            axis, reached, (tlo, thi) = problem
            raise NcError(path, block.source.first_line, 1, axis.upper(),
                          f"{axis.upper()} travel limit exceeded: the path reaches "
                          f"{reached:.4f} mm, travel is [{tlo:g}, {thi:g}] mm")
        _add_motion(summary, block, length)
        for i in range(3):
            lo[i], hi[i] = min(lo[i], box[0][i]), max(hi[i], box[1][i])
    summary.blocks = dict(sorted(kinds.items()))
    for i, name in enumerate(_AXES):
        if config.has_axis(name):
            summary.extents_mm[name] = [lo[i], hi[i]]
            summary.travel_mm[name] = list(config.axis(name).travel_mm)
    return summary


def _add_motion(summary: CheckSummary, block: NcBlock, length: float) -> None:
    summary.path_length_mm += length
    summary.nominal_time_s += length / block.feed_mm_s  # type: ignore[union-attr]
    if isinstance(block, LineBlock) and block.rapid:
        summary.rapid_length_mm += length
    else:
        summary.feed_length_mm += length
    if isinstance(block, NurbsBlock):
        summary.nurbs_blocks += 1
        summary.nurbs_control_points += block.control_points.shape[0]


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
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("program", help="G-code program file")
    parser.add_argument("--config", help="machine config file or built-in name")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")


def run(args: argparse.Namespace) -> int:
    try:
        config = load_config(args.config)
        summary = check_program(args.program, config)
    except ConfigError as exc:
        print(f"cncctl: config error: {exc}", file=sys.stderr)
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
