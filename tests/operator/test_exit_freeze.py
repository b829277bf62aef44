"""`cncctl` freezes its objects as it ends (the exit frees them: no last collection scans them
first); main() called in-process with its arguments leaves the caller's collector alone."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

_PROBE = """
import atexit, gc, sys
from controller.operator.cli import main
atexit.register(lambda: print("frozen", gc.get_freeze_count()))
if sys.argv[1] == "own":
    sys.argv[1:] = sys.argv[2:]
    main()
else:
    main(sys.argv[2:])
"""


def _frozen(tmp_path: Path, how: str) -> int:
    program = tmp_path / "line.nc"
    program.write_text("G21 G90 F600\nG1 X1\nM2\n")
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, how, "check", str(program), "--config", "xy_table"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        check=True,
    )
    return int(done.stdout.split("frozen")[-1])


def test_cncctl_freezes_its_objects_as_it_ends(tmp_path: Path) -> None:
    assert _frozen(tmp_path, "own") > 1000


def test_main_called_with_arguments_freezes_nothing(tmp_path: Path) -> None:
    assert _frozen(tmp_path, "args") == 0
