"""Long programs: `cncctl simulate` and `cncctl run --virtual-time` on 1k-1M G1 lines and
1-1000 airfoils, each command a process of its own: CPU time, real-time factor, peak RSS, rounds.

    python bench/long_programs.py [--quick] [--markdown] [--only NAME ...] [--keep DIR]
                                  [--commands simulate,run]

Programs (written seeded into a temporary directory, or --keep DIR):
- airfoil_xN: nc_programs/naca2415.nc's G6.2 block N times in a row, its last control point
  moved onto its first (0.6 um) so that each copy starts where the last one ends;
  airfoilscaled_xN: the same, copy k scaled by 1 - 0.2 k / N, so no two blocks repeat;
- walk_N: a G1 random walk of N lines of 0.05-0.5 mm, the heading turning by up to 30 degrees
  a line, at F3500 under G64, steered back (as sharply) 20 mm inside the travel of
  config/xy_table.yaml.

Per process (os.wait4 on the child: its own CPU and that of the children it waited for; the
child is forked by a small launcher so that its peak RSS is its own, see measure()):
- CPU = user + system time of the whole process tree;
- RTF = motion time / CPU time (and motion time / wall time, the machine being shared);
- peak RSS: `simulate`'s own; `run` prints each of its three processes' (interpreter,
  generator, motion), the largest is shown with all three;
- dynamics rounds: from `simulate --stats`, the largest and the mean per look-ahead window;
- planning/block: `simulate`'s planning CPU (the generator alone, no start-up, parsing or
  servo model) per block, the figure to compare between lengths.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
AIRFOIL = REPO / "nc_programs" / "naca2415.nc"
SEED = 19
FULL = ("airfoil_x1", "airfoil_x1000", "airfoilscaled_x1000", "walk_1k", "walk_10k", "walk_100k",
        "walk_1m")
QUICK = ("airfoil_x1", "airfoil_x10", "walk_1k", "walk_10k")
TURN_DEG = 30.0
STEP_MM = (0.05, 0.5)
MARGIN_MM = 10.0


def write_airfoil(path: Path, copies: int, scaled: bool = False) -> int:
    """The airfoil's NURBS block `copies` times; returns the number of NURBS blocks. Scaled:
    copy k is scaled about its trailing edge (the origin) by 1 - 0.2 k / copies, so that no
    two blocks are the same (the windows of a long run share repeated geometry, repeats.py)."""
    lines = AIRFOIL.read_text(encoding="utf-8").splitlines()
    first = next(i for i, t in enumerate(lines) if t.startswith("G6.2 P"))
    last = max(i for i, t in enumerate(lines) if t.startswith("G6.2 K"))
    block = [t.replace("X0.000042 Y0.000590", "X0.000000 Y0.000000")
             for t in lines[first:last + 1]]
    with path.open("w", encoding="ascii") as f:
        f.write("\n".join(lines[:first]) + "\n")
        for k in range(copies):
            f.write("\n".join(_scaled(block, 1.0 - 0.2 * k / copies) if scaled else block)
                    + "\n")
        f.write("M2\n")
    return copies


def _scaled(block: list[str], factor: float) -> list[str]:
    """The block's X and Y words multiplied by factor (weights and knots unchanged)."""
    def scale(match: re.Match[str]) -> str:
        return f"{match.group(1)}{float(match.group(2)) * factor:.6f}"
    return [re.sub(r"([XY])(-?\d+\.\d+)", scale, t) for t in block]


def write_walk(path: Path, n_lines: int, seed: int = SEED) -> int:
    """A seeded G1 random walk inside the X-Y table's travel; returns the number of G1 lines.

    Each line turns the heading by up to TURN_DEG; outside the inner box (MARGIN_MM inside the
    travel) the turn steers towards the middle instead, by at most as much, so the walk never
    reverses sharply (no stops) and stays a few mm outside that box at most."""
    import numpy as np

    from controller.config import load_config

    config = load_config(None)
    lo = max(config.axis("x").travel_mm[0], config.axis("y").travel_mm[0]) + 2 * MARGIN_MM
    hi = min(config.axis("x").travel_mm[1], config.axis("y").travel_mm[1]) - 2 * MARGIN_MM
    rng = np.random.default_rng(seed)
    steps = rng.uniform(*STEP_MM, n_lines)
    turns = np.radians(rng.uniform(-TURN_DEG, TURN_DEG, n_lines))
    limit = math.radians(TURN_DEG)
    x = y = heading = 0.0
    with path.open("w", encoding="ascii") as f:
        f.write("G17 G21 G90 G64\nF3500\nG0 X0 Y0\n")
        for step, turn in zip(steps.tolist(), turns.tolist(), strict=True):
            if lo < x < hi and lo < y < hi:
                heading += turn
            else:  # steer towards the middle
                off = math.remainder(math.atan2(-y, -x) - heading, math.tau)
                heading += max(-limit, min(limit, off))
            x, y = x + step * math.cos(heading), y + step * math.sin(heading)
            f.write(f"G1 X{x:.4f} Y{y:.4f}\n")
        f.write("M2\n")
    return n_lines


def write_program(name: str, directory: Path) -> tuple[Path, int]:
    """airfoil_xN, airfoilscaled_xN or walk_N (N may end in k or m): the file and its count of
    motion blocks."""
    kind, _, size = name.partition("_")
    count = int(size.lower().lstrip("x").replace("k", "000").replace("m", "000000"))
    path = directory / f"{name}.nc"
    if kind.startswith("airfoil"):
        return path, write_airfoil(path, count, scaled=kind == "airfoilscaled")
    return path, write_walk(path, count)


def measure(cmd: list[str], out_path: Path) -> dict[str, Any]:
    """Run cmd (stdout to a file) under this script's --launch mode: wall, CPU, peak RSS.

    A child's ru_maxrss starts from its parent's high-water mark (Linux keeps it across fork
    and exec), so the command is forked by a small launcher process, not by this one (which
    held the programs it wrote), and the launcher reports the command's os.wait4 usage."""
    usage_path = out_path.with_suffix(".usage.json")
    t0 = time.perf_counter()
    with out_path.open("w", encoding="utf-8") as out:
        proc = subprocess.run([sys.executable, __file__, "--launch", str(usage_path), "--", *cmd],
                              cwd=REPO, stdout=out, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    usage = json.loads(usage_path.read_text(encoding="utf-8"))
    return {"exit": usage["exit"], "wall_s": wall, "cpu_s": usage["cpu_s"],
            "maxrss_mb": usage["maxrss_mb"], "stderr": proc.stderr.strip()[-400:],
            "stdout": out_path.read_text(encoding="utf-8")}


def launch(usage_path: str, cmd: list[str]) -> int:
    """--launch: fork and exec cmd, wait for it with os.wait4, write its usage as JSON."""
    pid = os.fork()
    if pid == 0:
        try:
            os.execv(cmd[0], cmd)
        finally:
            os._exit(127)
    _, status, usage = os.wait4(pid, 0)
    code = os.waitstatus_to_exitcode(status)
    Path(usage_path).write_text(json.dumps({
        "exit": code, "cpu_s": usage.ru_utime + usage.ru_stime,
        "maxrss_mb": usage.ru_maxrss / 1024.0}), encoding="utf-8")
    return 0


def cncctl(*args: str) -> list[str]:
    return [sys.executable, "-m", "controller.operator.cli", *args]


def bench_simulate(path: Path, work: Path) -> dict[str, Any]:
    m = measure(cncctl("simulate", str(path), "--json", "--stats"), work / "simulate.json")
    r = json.loads(m["stdout"]) if m["stdout"].strip().startswith("{") else {}
    stats = r.get("stats", {})
    return {**m, "motion_s": r.get("motion_time_s"), "rss_mb": m["maxrss_mb"],
            "rss_detail": "", "rounds_max": stats.get("dynamics_rounds_max"),
            "rounds_mean": stats.get("dynamics_rounds_mean"), "windows": stats.get("windows"),
            "true_um": (r.get("contour_error_true_um") or {}).get("max"),
            "limit_met": r.get("contour_limit_met"), "plan_cpu_s": r.get("planning_cpu_s")}


def bench_run(path: Path, work: Path) -> dict[str, Any]:
    m = measure(cncctl("run", str(path), "--virtual-time", "--json"), work / "run.json")
    events = [json.loads(t) for t in m["stdout"].splitlines() if t.startswith("{")]
    final = events[-1] if events else {}
    rss = final.get("peak_rss_mb", {})
    detail = "/".join(f"{rss[k]:.0f}" for k in ("interpreter", "generator", "motion") if k in rss)
    return {**m, "motion_s": final.get("motion_time_s"), "rss_mb": max(rss.values(), default=0.0)
            if rss else m["maxrss_mb"], "rss_detail": detail, "rounds_max": None,
            "rounds_mean": None, "windows": None,
            "true_um": (final.get("contour_error_um") or {}).get("max"),
            "limit_met": final.get("event") == "done", "plan_cpu_s": None}


def row(name: str, blocks: int, command: str, r: dict[str, Any]) -> dict[str, Any]:
    motion = r.get("motion_s") or 0.0
    return {"program": name, "blocks": blocks, "command": command, "exit": r["exit"],
            "motion_s": motion, "cpu_s": r["cpu_s"], "wall_s": r["wall_s"],
            "rtf_cpu": motion / r["cpu_s"] if r["cpu_s"] else 0.0,
            "rtf_wall": motion / r["wall_s"] if r["wall_s"] else 0.0,
            "cpu_per_block_ms": 1000.0 * r["cpu_s"] / max(blocks, 1),
            "plan_per_block_ms": None if r["plan_cpu_s"] is None else
            1000.0 * r["plan_cpu_s"] / max(blocks, 1),
            "rss_mb": r["rss_mb"], "rss_detail": r["rss_detail"], "rounds_max": r["rounds_max"],
            "rounds_mean": r["rounds_mean"], "windows": r["windows"], "true_um": r["true_um"],
            "stderr": r["stderr"] if r["exit"] else ""}


COLUMNS = ("program", "blocks", "command", "motion (s)", "CPU (s)", "wall (s)", "RTF CPU",
           "RTF wall", "CPU/block (ms)", "planning/block (ms)", "peak RSS (MB)",
           "rounds max / mean (windows)", "max error (um)", "exit")


def cells(r: dict[str, Any]) -> list[str]:
    rounds = "-" if r["rounds_max"] is None else \
        f"{r['rounds_max']} / {r['rounds_mean']:.2f} ({r['windows']})"
    rss = f"{r['rss_mb']:.0f}" + (f" ({r['rss_detail']})" if r["rss_detail"] else "")
    err = "-" if r["true_um"] is None else f"{r['true_um']:.2f}"
    return [r["program"], f"{r['blocks']:,}", r["command"], f"{r['motion_s']:.1f}",
            f"{r['cpu_s']:.2f}", f"{r['wall_s']:.2f}", f"{r['rtf_cpu']:.0f}",
            f"{r['rtf_wall']:.0f}", f"{r['cpu_per_block_ms']:.3f}",
            "-" if r["plan_per_block_ms"] is None else f"{r['plan_per_block_ms']:.3f}", rss,
            rounds, err, str(r["exit"])]


def print_table(rows: list[dict[str, Any]], markdown: bool) -> None:
    table = [cells(r) for r in rows]
    if markdown:
        print("| " + " | ".join(COLUMNS) + " |")
        print("|" + "---|" * len(COLUMNS))
        for t in table:
            print("| " + " | ".join(t) + " |")
        return
    widths = [max(len(c), *(len(t[i]) for t in table)) for i, c in enumerate(COLUMNS)]
    print("  ".join(c.ljust(w) for c, w in zip(COLUMNS, widths, strict=True)))
    for t in table:
        print("  ".join(c.ljust(w) for c, w in zip(t, widths, strict=True)))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--launch"]:
        return launch(argv[1], argv[3:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    ap.add_argument("--only", nargs="+", metavar="NAME",
                    help="programs by name (airfoil_xN, airfoilscaled_xN, walk_N; N may end in "
                         "k or m)")
    ap.add_argument("--commands", default="simulate,run", help="simulate, run or both")
    ap.add_argument("--markdown", action="store_true", help="print a markdown table")
    ap.add_argument("--keep", metavar="DIR", help="write the programs (and outputs) here")
    ap.add_argument("--json", metavar="FILE", help="also write every row as JSON")
    args = ap.parse_args(argv)
    names = args.only or (QUICK if args.quick else FULL)
    commands = [c for c in args.commands.split(",") if c]
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        for name in names:
            path, blocks = write_program(name, root)
            for command in commands:
                work = root / f"{name}.{command}"
                work.mkdir(exist_ok=True)
                r = bench_simulate(path, work) if command == "simulate" else bench_run(path, work)
                rows.append(row(name, blocks, command, r))
                print(f"{name} {command}: " + ", ".join(
                    f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                    for k, v in rows[-1].items() if k not in ("program", "command")),
                    file=sys.stderr, flush=True)
    print_table(rows, args.markdown)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0 if all(r["exit"] in (0, 1) for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
