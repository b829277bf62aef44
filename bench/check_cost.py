"""Instructions of the check `cncctl simulate` runs before planning: read, check, keep.

Usage: python bench/check_cost.py PROGRAM [PROGRAM ...] [--tree DIR ...]
For each tree (its `controller` imported through PYTHONPATH; default: this repository) and
program, valgrind's callgrind counts a process that imports the command and checks the
program, and one that only imports: their difference is the check's. Counts do not move
with the machine's load (Python's hash seed is fixed); needs valgrind.
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
DRIVER = """import sys
from controller.config import load_config
from controller.operator.simulate_cmd import _check_whole_program
config = load_config(None)
if sys.argv[2] == "check":
    _check_whole_program(sys.argv[1], config)
"""


def _instructions(tree: Path, driver: Path, program: str, what: str, out: Path) -> int:
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONHASHSEED="0")
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # bytecode cached, as an installed cncctl has it
    argv = [
        "valgrind",
        "--tool=callgrind",
        f"--callgrind-out-file={out}",
        sys.executable,
        str(driver),
        program,
        what,
    ]
    done = subprocess.run(
        argv, env=env, cwd=driver.parent, capture_output=True, text=True, check=True
    )
    return int(re.search(r"Collected : (\d+)", done.stderr).group(1))  # type: ignore[union-attr]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("programs", nargs="+")
    ap.add_argument("--tree", type=Path, nargs="+", default=[REPO])
    args = ap.parse_args(argv)
    if shutil.which("valgrind") is None:
        print("bench/check_cost.py needs valgrind", file=sys.stderr)
        return 2
    print("| tree | program | imports (M) | check (M) |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        driver = Path(tmp) / "check_driver.py"
        driver.write_text(DRIVER, encoding="utf-8")
        for program in args.programs:
            for tree in args.tree:
                base = _instructions(tree, driver, program, "import", Path(tmp) / "cg")
                full = _instructions(tree, driver, program, "check", Path(tmp) / "cg")
                name = Path(program).name
                print(f"| {tree} | {name} | {base / 1e6:,.0f} | {(full - base) / 1e6:,.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
