"""Instructions per cold ph-lookahead plan of a program, counted by valgrind (callgrind).

Usage: python bench/instructions.py [PROGRAM] [--plans N]
Unlike CPU time, the count does not change with the machine's load, so it is how changes to the
generator's speed are compared. Python start-up and imports are taken out by counting a run
with 1 plan and one with 1 + N plans; the difference is divided by N. Needs valgrind.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_PLAN = """
import sys
from controller.config import load_config
from controller.generator.feed.planner import clear_memo
from controller.generator.plan import plan_program
from controller.interpreter.program import read_program
config = load_config()
for _ in range(int(sys.argv[2])):
    clear_memo()
    list(plan_program(read_program(sys.argv[1], config), config, "ph-lookahead"))
"""


def _instructions(program: str, plans: int, script: Path, out_dir: Path) -> int:
    """Instructions of a whole run that plans the program `plans` times."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(
        ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_dir / f'cg.{plans}'}",
         sys.executable, str(script), program, str(plans)],
        capture_output=True, text=True, env=env, cwd=REPO, check=True)
    found = re.search(r"Collected : (\d+)", done.stderr)
    if found is None:
        raise RuntimeError(f"no instruction count in valgrind's output:\n{done.stderr[-2000:]}")
    return int(found.group(1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("program", nargs="?", type=Path, default=REPO / "nc_programs/naca2415.nc")
    ap.add_argument("--plans", type=int, default=3, help="plans counted after the first")
    args = ap.parse_args(argv)
    if shutil.which("valgrind") is None:
        print("bench/instructions.py needs valgrind (apt install valgrind)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "plan.py"
        script.write_text(_PLAN)
        program = str(args.program.resolve())  # the runs start in the repo, not here
        one = _instructions(program, 1, script, Path(tmp))
        more = _instructions(program, 1 + args.plans, script, Path(tmp))
    print(f"{args.program.name}: {(more - one) / args.plans / 1e6:.1f} M instructions per cold "
          f"ph-lookahead plan (callgrind, {args.plans} plans after the first)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
