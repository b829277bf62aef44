"""LinuxCNC's rs274 as the oracle: its canonical moves of each program against our blocks.

Usage: python bench/rs274_oracle.py [--config xyz_mill] [--rs274 PATH] [--results FILE] DIR|FILE...

For every G-code file (.nc .ngc .gcode .tap .cnc under each DIR) it runs `rs274 -g` (from
Debian's linuxcnc-uspace; a tool table with tools 1-999 so that a T word is never refused for
want of one) and our `cncctl check` path (read_program and the travel check), then compares the
STRAIGHT_TRAVERSE, STRAIGHT_FEED and ARC_FEED calls with our LineBlock, ArcBlock and HelixBlock: end
points, arc centres and turns, and feeds, each to 1 um (plus the rounding of rs274's four
printed decimals: 0.05 um in mm, 1.27 um in inch programs). rs274 prints in the program's units
(USE_LENGTH_UNITS); they are converted to mm. Zero-length traverses that rs274 prints (G28
through the point where the tool stands, a `G0` with no axis words) are dropped, as we drop them.
A NURBS (G5.1, G5.2) is compared by its place among the moves only: rs274 prints
`NURBS_FEED(count, ...)` without its control points. A program with NURBS is not-compared when
all its other moves are the same (they show where each side ends each NURBS), else differ.
A program that probes (G38.x) and differs is compared up to its first probe (not-compared when
those moves are the same): rs274 standalone simulates the probe tripping 0.01 in (0.254 mm)
short of its end point, our check takes it to the end, so positions read after it differ by
design. A program with an `o<name> call` runs in rs274 with an INI whose
[RS274NGC]SUBROUTINE_PATH is the program's folder, where our check finds `name.ngc`.

Each file is one of: same (both accept, same moves), differ (both accept, the first move that
differs is shown), rs274-only, ours-only (with our warning rule), both-refuse, not-compared. The
last line printed is a JSON summary.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from dataclasses import dataclass, field

from controller.blocks import ArcBlock, HelixBlock, LineBlock, NurbsBlock, ProbeBlock
from controller.config import MachineConfig, load_config
from controller.errors import CncError
from controller.interpreter.program import read_program
from controller.operator.check_cmd import check_program

EXTS = (".nc", ".ngc", ".gcode", ".tap", ".cnc")
TOLERANCE_MM = 1e-3
RS274_TIMEOUT_S = 60.0
_CALL_RE = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z0-9_]+)\((.*)\)\s*$")
_MM_PER_UNIT = {"CANON_UNITS_MM": 1.0, "CANON_UNITS_INCHES": 25.4, "CANON_UNITS_CM": 10.0}
# ARC_FEED's first and second axes in each plane (rs274's canon): indices into (x, y, z).
_PLANE_AXES = {"CANON_PLANE_XY": (0, 1, 2), "CANON_PLANE_YZ": (1, 2, 0),
               "CANON_PLANE_XZ": (2, 0, 1)}
# Our HelixBlock's planes (controller/blocks.PLANE_AXES: the same axis order as rs274's).
_CANON_PLANE = {"G17": "CANON_PLANE_XY", "G18": "CANON_PLANE_XZ", "G19": "CANON_PLANE_YZ"}


@dataclass(slots=True)
class Move:
    """One move in mm: kind G0, G1 or ARC; for arcs the centre in the plane and the turns."""

    kind: str
    end_mm: tuple[float, float, float]
    feed_mm_s: float = 0.0
    centre_mm: tuple[float, float] | None = None
    rotation: int = 0  # LinuxCNC: -1 one clockwise turn, 2 two counter-clockwise turns ...
    plane: str = "CANON_PLANE_XY"
    unit_mm: float = 1.0  # mm per printed unit, for the rounding allowance


@dataclass(slots=True)
class Oracle:
    accepted: bool
    moves: list[Move] = field(default_factory=list)
    message: str = ""
    nurbs: bool = False
    probe_at: int | None = None  # moves before the first probe (None: no probe)


def tool_table(folder: str) -> str:
    path = os.path.join(folder, "tools.tbl")
    with open(path, "w", encoding="ascii") as f:
        f.writelines(f"T{n} P{n} D0.1 Z0 ;\n" for n in range(1, 1000))
    return path


def sub_ini(folder: str, program: str) -> str:
    """An INI whose SUBROUTINE_PATH is the program's folder (our check looks there too)."""
    path = os.path.join(folder, "sub.ini")
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"[RS274NGC]\nSUBROUTINE_PATH = {os.path.dirname(os.path.abspath(program))}\n")
    return path


def _calls_by_name(program: str) -> bool:
    """Whether the program has an `o<name> call` (which may be of a subroutine file)."""
    with open(program, encoding="utf-8", errors="replace") as f:
        return _NAMED_CALL_RE.search(f.read()) is not None


_NAMED_CALL_RE = re.compile(r"o\s*<[^>]*>\s*call", re.IGNORECASE)


def run_rs274(rs274: str, program: str, folder: str) -> Oracle:
    """rs274's canonical calls for `program`, run in `folder` (no parameter file there).

    HOME is `folder` too: rs274 keeps its tool table in $HOME/.tool.mmap, truncated by each run
    that starts, so two runs sharing a HOME (pytest's workers) crash each other with SIGBUS."""
    try:
        ini = ["-i", sub_ini(folder, program)] if _calls_by_name(program) else []
        proc = subprocess.run([rs274, "-g", "-t", tool_table(folder), *ini,
                               os.path.abspath(program)],
                              cwd=folder, env={**os.environ, "HOME": folder},
                              capture_output=True, text=True, errors="replace",
                              timeout=RS274_TIMEOUT_S, stdin=subprocess.DEVNULL, check=False)
    except subprocess.TimeoutExpired:
        return Oracle(False, message=f"rs274 ran over {RS274_TIMEOUT_S:g} s")
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and ln != "executing"]
        return Oracle(False, message=lines[0] if lines else f"rs274 exit {proc.returncode}")
    return parse_calls(proc.stdout)


def parse_calls(text: str) -> Oracle:
    """The moves of rs274's printout in machine mm. rs274 prints positions in the work frame
    (program coordinates); its SET_G5X_OFFSET and SET_G92_OFFSET calls give the offsets to add,
    in the units in force when they are printed (a later G20 or G21 does not print them again)."""
    oracle = Oracle(True)
    unit = 1.0
    feed = 0.0
    plane = "CANON_PLANE_XY"
    g5x_mm = [0.0, 0.0, 0.0]
    g92_mm = [0.0, 0.0, 0.0]

    def machine(v: list[float]) -> tuple[float, float, float]:
        return (v[0] * unit + g5x_mm[0] + g92_mm[0], v[1] * unit + g5x_mm[1] + g92_mm[1],
                v[2] * unit + g5x_mm[2] + g92_mm[2])

    for line in text.splitlines():
        m = _CALL_RE.match(line)
        if m is None:
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            unit = _MM_PER_UNIT.get(args.strip(), 1.0)
        elif name == "SET_FEED_RATE":
            feed = float(args)
        elif name == "SELECT_PLANE":
            plane = args.strip()
        elif name == "SET_G5X_OFFSET":
            g5x_mm = [float(a) * unit for a in args.split(",")[1:4]]
        elif name == "SET_G92_OFFSET":
            g92_mm = [float(a) * unit for a in args.split(",")[:3]]
        elif name.startswith("NURBS"):
            oracle.nurbs = True
            oracle.moves.append(Move("NURBS", (math.nan,) * 3, feed * unit / 60.0, unit_mm=unit))
        elif name == "STRAIGHT_PROBE" and oracle.probe_at is None:
            oracle.probe_at = len(collapse(list(oracle.moves)))
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            v = [float(a) for a in args.split(",")]
            kind = "G0" if name == "STRAIGHT_TRAVERSE" else "G1"
            oracle.moves.append(Move(kind, machine(v), feed * unit / 60.0, unit_mm=unit))
        elif name == "ARC_FEED":
            v = [float(a) for a in args.split(",")]
            first, second, third = _PLANE_AXES.get(plane, (0, 1, 2))
            work = [0.0, 0.0, 0.0]
            work[first], work[second], work[third] = v[0], v[1], v[5]
            centre = [0.0, 0.0, 0.0]
            centre[first], centre[second] = v[2], v[3]
            c = machine(centre)
            oracle.moves.append(Move("ARC", machine(work), feed * unit / 60.0,
                                     (c[first], c[second]), int(v[4]), plane, unit))
    oracle.moves = collapse(oracle.moves)
    return oracle


def collapse(moves: list[Move], start: tuple[float, float, float] = (0.0, 0.0, 0.0)
             ) -> list[Move]:
    """Drop straight moves that end where the last kept move ended (within the printing
    allowance): zero-length moves, and the ones rs274's four decimals make zero-length."""
    kept: list[Move] = []
    pos = start
    for move in moves:
        tol = TOLERANCE_MM / 2 + 0.5e-4 * move.unit_mm
        if move.kind not in ("ARC", "NURBS") and max(abs(a - b) for a, b in zip(move.end_mm, pos,
                                                                  strict=True)) <= tol:
            continue
        kept.append(move)
        pos = move.end_mm
    return kept


def run_ours(program: str, config: MachineConfig) -> Oracle:
    """Our check (the same as `cncctl check`) and the moves of our blocks."""
    try:
        check_program(program, config, summary=False)
        blocks = list(read_program(program, config))
    except CncError as exc:
        return Oracle(False, message=str(exc))
    ours = Oracle(True)
    nurbs_source = None  # one NURBS of the program may be several blocks (split at corners)
    for block in blocks:
        if isinstance(block, NurbsBlock):
            ours.nurbs = True
            if block.source != nurbs_source:
                ours.moves.append(Move("NURBS", block.end, block.feed_mm_s))
            ours.moves[-1].end_mm = block.end
        elif isinstance(block, ProbeBlock) and ours.probe_at is None:
            ours.probe_at = len(collapse(list(ours.moves)))
        elif isinstance(block, LineBlock):
            ours.moves.append(Move("G0" if block.rapid else "G1", tuple(block.end),
                                   block.feed_mm_s))
        elif isinstance(block, ArcBlock | HelixBlock):
            turns = block.turns + 1
            plane = _CANON_PLANE[block.plane] if isinstance(block, HelixBlock) else \
                "CANON_PLANE_XY"
            ours.moves.append(Move("ARC", tuple(block.end), block.feed_mm_s,
                                   tuple(block.center), -turns if block.clockwise else turns,
                                   plane))
        nurbs_source = block.source if isinstance(block, NurbsBlock) else None
    ours.moves = collapse(ours.moves)
    return ours


def first_difference(theirs: list[Move], ours: list[Move]) -> str | None:
    """None when the two lists are the same moves; else what differs first. A straight move
    shorter than the printing allowance on one side only is passed over: rs274's four decimals
    make some of an inch program's sub-micrometre moves zero-length, and not others. rs274
    prints no NURBS end: where ours ended stands for it (a zero-length move that rs274 prints
    after it, to where it ended, is passed over only if it goes to where ours ended)."""
    i = j = 0
    last_a = last_b = (0.0, 0.0, 0.0)
    while i < len(theirs) and j < len(ours):
        a, b = theirs[i], ours[j]
        why = _differs(a, b)
        if why is None:
            last_a, last_b = b.end_mm if a.kind == "NURBS" else a.end_mm, b.end_mm
            i, j = i + 1, j + 1
        elif _tiny(b, last_b, a.unit_mm):
            last_b = b.end_mm
            j += 1
        elif _tiny(a, last_a, a.unit_mm):
            last_a = a.end_mm
            i += 1
        else:
            return f"move {i + 1}: {why}"
    rest_a = [m for m in theirs[i:] if not _tiny(m, last_a, m.unit_mm)]
    rest_b = [m for m in ours[j:] if not _tiny(m, last_b, 1.0)]
    if rest_a or rest_b:
        return f"rs274 has {len(rest_a)} more moves, we have {len(rest_b)} more"
    return None


def _tiny(move: Move, last: tuple[float, float, float], unit_mm: float) -> bool:
    allowance = TOLERANCE_MM + 1e-4 * unit_mm
    return move.kind not in ("ARC", "NURBS") and max(abs(p - q) for p, q in zip(move.end_mm, last,
                                                                  strict=True)) <= allowance


def _differs(a: Move, b: Move) -> str | None:
    tol = TOLERANCE_MM + 0.5e-4 * a.unit_mm
    if a.kind != b.kind:
        return f"rs274 {a.kind} to {_show(a.end_mm)}, we {b.kind} to {_show(b.end_mm)}"
    if a.kind == "NURBS":
        return _differs_nurbs(a, b)
    if max(abs(p - q) for p, q in zip(a.end_mm, b.end_mm, strict=True)) > tol:
        return f"{a.kind} end: rs274 {_show(a.end_mm)}, we {_show(b.end_mm)}"
    if a.kind != "G0" and abs(a.feed_mm_s - b.feed_mm_s) > 0.5e-4 * a.unit_mm / 60 + 1e-9:
        return f"{a.kind} feed: rs274 {a.feed_mm_s * 60:.4f} mm/min, we {b.feed_mm_s * 60:.4f}"
    if a.kind == "ARC" and a.plane != b.plane:
        return f"arc plane: rs274 {a.plane}, we {b.plane}"
    if a.kind == "ARC":
        if max(abs(p - q) for p, q in zip(a.centre_mm, b.centre_mm, strict=True)) > tol:
            return f"arc centre: rs274 {_show(a.centre_mm)}, we {_show(b.centre_mm)}"
        if a.rotation != b.rotation:
            return f"arc turns: rs274 {a.rotation}, we {b.rotation}"
    return None


def _differs_nurbs(a: Move, b: Move) -> str | None:
    """rs274 prints no NURBS geometry: only the feed can be compared."""
    if abs(a.feed_mm_s - b.feed_mm_s) > 0.5e-4 * a.unit_mm / 60 + 1e-9:
        return f"NURBS feed: rs274 {a.feed_mm_s * 60:.4f} mm/min, we {b.feed_mm_s * 60:.4f}"
    return None


def _show(p: tuple[float, ...]) -> str:
    return "(" + ", ".join(f"{v:.4f}" for v in p) + ")"


def compare(program: str, config: MachineConfig, rs274: str, folder: str) -> dict:
    theirs = run_rs274(rs274, program, folder)
    ours = run_ours(program, config)
    row = {"file": program, "rs274": theirs.message, "ours": ours.message}
    if theirs.accepted and ours.accepted:
        diff = first_difference(theirs.moves, ours.moves)
        if (theirs.nurbs or ours.nurbs) and diff is None:
            count = sum(m.kind == "NURBS" for m in ours.moves)
            row["status"] = "not-compared"
            row["why"] = (f"NURBS: {count} NURBS in their places, the "
                          f"{len(ours.moves) - count} other moves the same")
        else:
            row["status"] = "differ" if diff else "same"
            row["why"] = diff or f"{len(ours.moves)} moves"
            if diff and (theirs.probe_at is not None or ours.probe_at is not None):
                _compare_to_probe(row, theirs, ours)
    elif theirs.accepted:
        row["status"] = "rs274-only"
    elif ours.accepted:
        row["status"] = "ours-only"
    else:
        row["status"] = "both-refuse"
    return row


def _compare_to_probe(row: dict, theirs: Oracle, ours: Oracle) -> None:
    """A program that probes and differs: the moves before its first probe (what follows
    depends on where each side takes the probe to trip)."""
    a = theirs.moves[:theirs.probe_at if theirs.probe_at is not None else len(theirs.moves)]
    b = ours.moves[:ours.probe_at if ours.probe_at is not None else len(ours.moves)]
    diff = first_difference(a, b)
    row["status"] = "differ" if diff else "not-compared"
    row["why"] = diff or f"probe: the {len(b)} moves before the first probe are the same"


def programs(paths: list[str]) -> list[str]:
    found: list[str] = []
    for path in paths:
        if os.path.isfile(path):
            found.append(path)
            continue
        for dirpath, dirnames, filenames in os.walk(path):
            dirnames.sort()
            found += [os.path.join(dirpath, n) for n in sorted(filenames)
                      if n.lower().endswith(EXTS)]
    return found


def find_rs274(explicit: str | None = None) -> str | None:
    return explicit or shutil.which("rs274") or (
        "/usr/bin/rs274" if os.access("/usr/bin/rs274", os.X_OK) else None)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("paths", nargs="+")
    parser.add_argument("--config", default="xyz_mill")
    parser.add_argument("--rs274", default=None)
    parser.add_argument("--results", default=None, help="one JSON line per file")
    args = parser.parse_args(argv)
    rs274 = find_rs274(args.rs274)
    if rs274 is None:
        print("rs274_oracle: no rs274 (apt-get install linuxcnc-uspace)", file=sys.stderr)
        return 1
    config = load_config(args.config)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for program in programs(args.paths):
            rows.append(compare(program, config, rs274, folder))
    report(rows)
    if args.results:
        with open(args.results, "w", encoding="utf-8") as f:
            f.writelines(json.dumps(r) + "\n" for r in rows)
    return 0


def report(rows: list[dict]) -> None:
    counts = Counter(r["status"] for r in rows)
    print(f"{'file':60} {'status':13} detail")
    for r in rows:
        detail = r.get("why") or r["ours"] or r["rs274"]
        if r["status"] == "ours-only":
            detail = "rs274: " + r["rs274"]
        print(f"{r['file'][-60:]:60} {r['status']:13} {detail[:110]}")
    accepted = counts["same"] + counts["differ"] + counts["rs274-only"] + counts["not-compared"]
    print()
    for status in ("same", "differ", "not-compared", "rs274-only", "ours-only", "both-refuse"):
        print(f"{status:13} {counts[status]:5}")
    summary = {"files": len(rows), "rs274_accepts": accepted, **dict(counts),
               "agreement": (counts["same"] / (accepted - counts["not-compared"])
                             if accepted - counts["not-compared"] else math.nan)}
    print(json.dumps(summary))


if __name__ == "__main__":
    sys.exit(main())
