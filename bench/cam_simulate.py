"""Every CAM program `cncctl check` accepts, simulated: within the contour limit, feed and
acceleration held, failures, time-outs, motion time and CPU, per source of the corpus.

    python bench/cam_simulate.py [--corpus DIR] [--linuxcnc [DIR]] [--config xyz_mill] [--workers 1]
        [--timeout 900] [--only TEXT ...] [--markdown] [--json FILE] [--log FILE [--reuse]]

The corpus: one subfolder per source (CAMotics, pcb2gcode, ...), `--corpus DIR` or $CAM_CORPUS
(not in the repository: without it the bench says so and exits 0). `--linuxcnc` adds LinuxCNC's
`nc_files` (default: `corpus/linuxcnc` beside it). Each program is checked (`cncctl check`),
each accepted one simulated (`cncctl simulate --json`), shortest first, each command a process
of its own. `--log FILE` appends each outcome as it ends; `--reuse` skips those FILE has.

Per program: simulated (exit 0 or 1 with figures), within the limit (exit 0: the tool's true
distance from the path within the contour error limit), feed held (the largest speed of the
reference at most the feed or rapid limit), acceleration held (its largest tangential
acceleration at most Amax), both to REL_TOL; CPU is simulate's user + system time (wait4),
planning CPU the generator's alone (simulate's figure). A failure is any other exit, with its
message's first line; a time-out is killed (`--timeout` CPU s, or ten times that of real time).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import IO

CORPUS = os.environ.get("CAM_CORPUS")  # the corpus folder, when --corpus is not given
EXTS = (".nc", ".ngc", ".gcode", ".tap", ".cnc")
REL_TOL = 1e-3  # finite differences of a 1 ms reference: a limit held to 0.1 %
CHECK_TIMEOUT_S = 120.0
POLL_S = 0.05
WALL_FACTOR = 10.0  # a shared machine: the real-time limit is 10 times the CPU time limit
MIN_BLOCKS = 200  # below, start-up dominates the CPU per block


@dataclass
class Outcome:
    """One program: what check and simulate said."""

    source: str
    program: str
    status: str = "refused"  # refused, ok, over_limit, failed, timeout, check_failed
    message: str = ""
    motion_time_s: float = 0.0
    true_error_um: float = 0.0
    max_feed_mm_s: float = 0.0
    max_accel_mm_s2: float = 0.0
    feed_held: bool = True
    accel_held: bool = True
    planning_cpu_s: float = 0.0
    cpu_s: float = 0.0
    wall_s: float = 0.0
    blocks: int = 0  # the NC blocks check reads (moves, dwells, outputs)


KEYS = {f.name for f in fields(Outcome)}


@dataclass
class Proc:
    """A finished (or killed) command: exit code, output, its own CPU time."""

    rc: int | None
    out: str
    err: str
    cpu_s: float
    wall_s: float


Limits = tuple[float, float]  # the feed (mm/s) and acceleration (mm/s^2) held to


def run_cmd(argv: list[str], timeout_s: float) -> Proc:
    """Run argv with its output in files; wait4 for its CPU. It may use timeout_s of CPU time
    (RLIMIT_CPU: the machine's load does not count) and WALL_FACTOR times that in real time;
    beyond either it is killed, by its pid."""
    with tempfile.TemporaryFile() as fo, tempfile.TemporaryFile() as fe:
        t0 = time.monotonic()
        p = subprocess.Popen(argv, stdout=fo, stderr=fe, stdin=subprocess.DEVNULL)
        cpu_limit = math.ceil(timeout_s)
        resource.prlimit(p.pid, resource.RLIMIT_CPU, (cpu_limit, cpu_limit + 5))
        rc, cpu_s = _wait(p.pid, t0 + WALL_FACTOR * timeout_s)
        wall_s = time.monotonic() - t0
        p.returncode = -1  # reaped here: Popen must not wait for it again
        out, err = (_text(f) for f in (fo, fe))
        return Proc(rc, out, err, cpu_s, wall_s)


def _text(f: IO[bytes]) -> str:
    f.seek(0)
    return f.read().decode(errors="replace")


def _wait(pid: int, deadline: float) -> tuple[int | None, float]:
    """(exit code, None when killed: at the deadline or by RLIMIT_CPU; its CPU seconds)."""
    killed = False
    while True:
        got, status, usage = os.wait4(pid, 0 if killed else os.WNOHANG)
        if got == pid:
            cpu_s = usage.ru_utime + usage.ru_stime
            rc = os.waitstatus_to_exitcode(status)
            return (None if killed or rc == -signal.SIGXCPU else rc), cpu_s
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            killed = True
            continue
        time.sleep(POLL_S)


def first_line(text: str) -> str:
    """The first non-blank line of a message (a traceback: its last line, the exception)."""
    lines = [t.strip() for t in text.splitlines() if t.strip()]
    if not lines:
        return ""
    return lines[-1] if lines[0].startswith("Traceback") else lines[0]


def cncctl(*args: str) -> list[str]:
    """The cncctl of this interpreter's environment, run as a module of this tree."""
    return [sys.executable, "-m", "controller.operator.cli", *args]


def check(path: Path, config: str) -> Proc:
    return run_cmd(cncctl("check", "--config", config, "--json", str(path)), CHECK_TIMEOUT_S)


def simulate(path: Path, config: str, timeout_s: float) -> Proc:
    return run_cmd(cncctl("simulate", "--config", config, "--json", str(path)), timeout_s)


def one(
    source: str, path: Path, root: Path, config: str, timeout_s: float, limits: Limits
) -> Outcome:
    """Check, then simulate if accepted."""
    o = Outcome(source, str(path.relative_to(root)))
    c = check(path, config)
    if c.rc == 2:
        return o
    if c.rc != 0:
        o.status, o.message = "check_failed", _why(c)
        return o
    o.blocks = sum(json.loads(c.out)["blocks"].values())
    s = simulate(path, config, timeout_s)
    o.cpu_s, o.wall_s = s.cpu_s, s.wall_s
    _figures(o, s, limits)
    return o


def _why(p: Proc) -> str:
    return "time-out" if p.rc is None else f"exit {p.rc}: {first_line(p.err or p.out)}"


def _figures(o: Outcome, s: Proc, limits: Limits) -> None:
    """Outcome of a simulate run from its exit code and JSON."""
    if s.rc is None:
        o.status = "timeout"
        o.message = f"killed after {s.cpu_s:.1f} s CPU, {s.wall_s:.0f} s"
        return
    if s.rc not in (0, 1):
        o.status, o.message = "failed", _why(s)
        return
    try:
        r = json.loads(s.out)
    except json.JSONDecodeError:
        o.status, o.message = "failed", f"exit {s.rc}, no JSON: {first_line(s.err)}"
        return
    o.motion_time_s = r["motion_time_s"]
    o.true_error_um = r["contour_error_true_um"]["max"]
    o.max_feed_mm_s, o.max_accel_mm_s2 = r["max_feed_mm_s"], r["max_tangential_accel_mm_s2"]
    o.planning_cpu_s = r["planning_cpu_s"]
    o.feed_held = o.max_feed_mm_s <= limits[0] * (1 + REL_TOL)
    o.accel_held = o.max_accel_mm_s2 <= limits[1] * (1 + REL_TOL)
    o.status = "ok" if s.rc == 0 else "over_limit"
    if s.rc == 1:
        o.message = first_line(s.err)


def config_limits(config: str) -> Limits:
    from controller.config import load_config

    ip = load_config(config).interpolator
    return max(ip.max_feed_mm_s, ip.rapid_feed_mm_s), ip.max_accel_mm_s2


def programs(root: Path, source: str | None) -> list[tuple[str, Path]]:
    """(source, path) of every G-code file under root; the source is the first folder, or
    `source` for all of them."""
    found = sorted(p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in EXTS)
    return [(source or p.relative_to(root).parts[0], p) for p in found]


@dataclass
class SourceRow:
    """The table's row for one source."""

    source: str
    files: int = 0
    accepted: int = 0
    simulated: int = 0
    within_limit: int = 0
    limits_held: int = 0
    max_error_um: float = 0.0
    failures: int = 0
    timeouts: int = 0
    motion_time_s: float = 0.0
    cpu_s: float = 0.0
    planning_cpu_s: float = 0.0
    problems: list[str] = field(default_factory=list)


def summarise(outcomes: list[Outcome]) -> list[SourceRow]:
    rows: dict[str, SourceRow] = {}
    for o in outcomes:
        _count(rows.setdefault(o.source, SourceRow(o.source)), o)
    total = SourceRow("all")
    for row in rows.values():
        _fold(total, row)
    return [*rows.values(), total]


def _count(row: SourceRow, o: Outcome) -> None:
    row.files += 1
    if o.status == "refused":
        return
    row.accepted += 1
    simulated = o.status in ("ok", "over_limit")
    row.simulated += simulated
    row.within_limit += o.status == "ok"
    row.limits_held += simulated and o.feed_held and o.accel_held
    row.failures += o.status in ("failed", "check_failed")
    row.timeouts += o.status == "timeout"
    row.max_error_um = max(row.max_error_um, o.true_error_um)
    row.motion_time_s += o.motion_time_s
    row.cpu_s += o.cpu_s
    row.planning_cpu_s += o.planning_cpu_s
    if o.status != "ok" or not (o.feed_held and o.accel_held):
        row.problems.append(_problem(o))


def _problem(o: Outcome) -> str:
    held = (
        ""
        if o.feed_held and o.accel_held
        else (f" (feed {o.max_feed_mm_s:.1f} mm/s, accel {o.max_accel_mm_s2:.0f} mm/s^2)")
    )
    what = o.message or f"{o.true_error_um:.1f} um"
    return f"{o.program}: {o.status}{held}: {what}"


def _fold(total: SourceRow, row: SourceRow) -> None:
    for f in fields(SourceRow):
        if f.name not in ("source", "max_error_um", "problems"):
            setattr(total, f.name, getattr(total, f.name) + getattr(row, f.name))
    total.max_error_um = max(total.max_error_um, row.max_error_um)
    total.problems += row.problems


HEAD = tuple(
    "source|files|accepted|simulated|within limit|limits held|max error um|failures|time-outs"
    "|motion s|CPU s|planning CPU s".split("|")
)


def cells(r: SourceRow) -> list[str]:
    counts = (r.files, r.accepted, r.simulated, r.within_limit, r.limits_held)
    ends = (r.failures, r.timeouts)
    times = (r.motion_time_s, r.cpu_s, r.planning_cpu_s)
    return [r.source, *map(str, counts), f"{r.max_error_um:.1f}", *map(str, ends)] + [
        f"{t:.0f}" for t in times
    ]


def text_table(rows: list[SourceRow]) -> str:
    table = [list(HEAD)] + [cells(r) for r in rows]
    widths = [max(len(t[i]) for t in table) for i in range(len(HEAD))]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(t, widths, strict=True)) for t in table)


def markdown_table(rows: list[SourceRow]) -> str:
    lines = ["| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
    lines += ["| " + " | ".join(cells(r)) + " |" for r in rows]
    return "\n".join(lines)


def slowest(outcomes: list[Outcome], n: int = 5) -> list[str]:
    """The n programs with the most planning CPU per block, the figure of a slow plan."""
    timed = [o for o in outcomes if o.cpu_s > 0 and o.blocks >= MIN_BLOCKS]
    timed.sort(key=lambda o: o.planning_cpu_s / o.blocks, reverse=True)
    return [
        f"{o.program}: {o.blocks} blocks, planning {o.planning_cpu_s:.1f} s CPU "
        f"({1e3 * o.planning_cpu_s / o.blocks:.2f} ms/block), all {o.cpu_s:.1f} s CPU, "
        f"motion {o.motion_time_s:.0f} s"
        for o in timed[:n]
    ]


def report(outcomes: list[Outcome], markdown: bool) -> str:
    rows = summarise(outcomes)
    out = [markdown_table(rows) if markdown else text_table(rows), ""]
    out += ["Not simulated within the limit, or a limit not held:"]
    out += [f"- {p}" for p in rows[-1].problems] or ["- none"]
    out += ["", "Most planning CPU per block:"] + [f"- {s}" for s in slowest(outcomes)]
    return "\n".join(out)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", type=Path, default=Path(CORPUS) if CORPUS else None)
    ap.add_argument(
        "--linuxcnc",
        type=Path,
        nargs="?",
        const=Path(),
        default=None,
        help="add LinuxCNC's nc_files (default: linuxcnc beside the corpus)",
    )
    ap.add_argument("--config", default="xyz_mill")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=900.0, help="CPU s per simulate")
    ap.add_argument("--only", nargs="*", default=[], help="programs whose path has TEXT")
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--json", type=Path, help="write every program's outcome and the table")
    ap.add_argument("--log", type=Path, help="append each program's outcome as it ends")
    ap.add_argument("--reuse", action="store_true", help="take the outcomes --log has")
    return ap.parse_args(argv)


def select(args: argparse.Namespace) -> list[tuple[str, Path, Path]]:
    """(source, path, root) of every program to run."""
    chosen = [(s, p, args.corpus) for s, p in programs(args.corpus, None)]
    if args.linuxcnc is not None:
        lc = args.linuxcnc if args.linuxcnc != Path() else args.corpus.parent / "linuxcnc"
        chosen += [(s, p, lc) for s, p in programs(lc, "linuxcnc")] if lc.is_dir() else []
    if args.only:
        chosen = [c for c in chosen if any(t in str(c[1]) for t in args.only)]
    return chosen


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.corpus is None or not args.corpus.is_dir():
        print(f"skipped: no corpus at {args.corpus} (--corpus DIR or $CAM_CORPUS)")
        return 0
    chosen = select(args)
    done = reused(args.log, {str(p) for _, p, _ in chosen}) if args.reuse else {}
    todo = [c for c in chosen if str(c[1]) not in done]
    outcomes = list(done.values()) + run_all(todo, args)
    print(
        f"cncctl simulate --config {args.config}, {len(outcomes)} programs, "
        f"time-out {args.timeout:g} s CPU, {args.workers} worker(s)"
    )
    print(report(outcomes, args.markdown))
    if args.json:
        rows = [asdict(r) for r in summarise(outcomes)]
        args.json.write_text(
            json.dumps({"programs": [asdict(o) for o in outcomes], "sources": rows}, indent=1),
            encoding="utf-8",
        )
    return 0


def run_all(todo: list[tuple[str, Path, Path]], args: argparse.Namespace) -> list[Outcome]:
    """Every program, shortest first (a failure shows early), each logged as it ends."""
    limits = config_limits(args.config)
    todo = sorted(todo, key=lambda c: c[1].stat().st_size)
    outcomes = []
    with ThreadPoolExecutor(max_workers=max(1, args.workers)) as pool:
        jobs = [
            pool.submit(one, s, p, root, args.config, args.timeout, limits) for s, p, root in todo
        ]
        for k, job in enumerate(as_completed(jobs)):
            outcomes.append(_progress(job.result(), k, len(jobs)))
            _log(args.log, todo[jobs.index(job)][1], outcomes[-1])
    return outcomes


def _log(log: Path | None, path: Path, o: Outcome) -> None:
    if log is not None:
        with log.open("a", encoding="utf-8") as f:
            f.write(json.dumps({"path": str(path), **asdict(o)}) + "\n")


def reused(log: Path | None, paths: set[str]) -> dict[str, Outcome]:
    """The outcomes --log FILE holds for these paths (the last one of each): --reuse."""
    if log is None or not log.exists():
        return {}
    out = {}
    for line in log.read_text(encoding="utf-8").splitlines():
        row = json.loads(line)
        path = row.pop("path")
        if path in paths:
            out[path] = Outcome(**{k: v for k, v in row.items() if k in KEYS})
    return out


def _progress(o: Outcome, k: int, n: int) -> Outcome:
    print(
        f"[{k + 1}/{n}] {o.program}: {o.status} {o.true_error_um:.1f} um "
        f"{o.cpu_s:.1f} s CPU {o.message}",
        file=sys.stderr,
        flush=True,
    )
    return o


if __name__ == "__main__":
    sys.exit(main())
