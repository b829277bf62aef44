"""Start-up cost of `cncctl simulate` and `cncctl run --virtual-time` on a one-line program.

Usage: python bench/startup.py [--runs N] [--callgrind] [--tree DIR ...]
Each command runs N times (the trees and commands in turn, so load affects them alike); the
CPU (user + system of the whole process tree) is given as min and median. With --callgrind
the instructions of the cncctl process itself (not the processes `run` forks) are counted
once by valgrind, which does not change with the machine's load. --tree compares source
trees (each one's `controller` imported through PYTHONPATH; default: this repository).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
COMMANDS = {
    "simulate": ["simulate", "{program}", "--json"],
    "run": ["run", "{program}", "--virtual-time", "--json"],
}


def _argv(command: str, program: Path) -> list[str]:
    words = [w.replace("{program}", str(program)) for w in COMMANDS[command]]
    return [sys.executable, "-m", "controller.operator.cli", *words]


def _env(tree: Path, socket_dir: Path) -> dict[str, str]:
    """The tree's code first; no cncd (a run would otherwise go through one)."""
    env = dict(os.environ, PYTHONPATH=str(tree), CNCD_SOCKET=str(socket_dir / "none.sock"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # bytecode cached, as an installed cncctl has it
    return env


def _cpu_s(argv: list[str], env: dict[str, str], cwd: Path) -> float:
    """User + system CPU of one run of argv and every process it started."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, env=env, cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _instructions(argv: list[str], env: dict[str, str], cwd: Path, out: Path) -> int:
    """Instructions of the cncctl process itself, counted by callgrind."""
    done = subprocess.run(
        ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}.%p", *argv],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        check=True,
    )
    pid = re.search(r"==(\d+)== Command:", done.stderr)
    found = pid and re.search(rf"=={pid.group(1)}== Collected : (\d+)", done.stderr)
    if not found:
        raise RuntimeError(f"no instruction count in valgrind's output:\n{done.stderr[-2000:]}")
    return int(found.group(1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--callgrind", action="store_true", help="also count instructions")
    ap.add_argument("--tree", type=Path, nargs="+", default=[REPO])
    ap.add_argument("--commands", default="simulate,run")
    args = ap.parse_args(argv)
    if args.callgrind and shutil.which("valgrind") is None:
        print("bench/startup.py --callgrind needs valgrind", file=sys.stderr)
        return 2
    commands = args.commands.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        program = work / "one.nc"
        program.write_text("G1 X1 F600\n")
        for tree in args.tree:  # compile each tree's bytecode once, outside the figures
            _cpu_s(_argv(commands[0], program), _env(tree, work), tree)
        cpu: dict[tuple[Path, str], list[float]] = {}
        for _ in range(args.runs):
            for tree in args.tree:
                for command in commands:
                    t_s = _cpu_s(_argv(command, program), _env(tree, work), tree)
                    cpu.setdefault((tree, command), []).append(t_s)
        print("| tree | command | CPU min (s) | CPU median (s) | instructions (M) |")
        print("|---|---|---|---|---|")
        for (tree, command), times in cpu.items():
            count = "-"
            if args.callgrind:
                n = _instructions(_argv(command, program), _env(tree, work), tree, work / "cg")
                count = f"{n / 1e6:,.0f}"
            print(
                f"| {tree} | {command} | {min(times):.3f} | {statistics.median(times):.3f} "
                f"| {count} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
