"""Shared by the homing tests: configs with homing sections, simulated peers in their process."""

from __future__ import annotations

import select
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from controller.config import MachineConfig, load_config

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-m", "controller.operator.cli"]
# X searches toward -1 (switch at -149, final -145), Y toward +1 (149, 145): as
# config/xy_table_switches.yaml.
HOMING = {"x": {"direction": -1, "search_mm_s": 20.0, "latch_mm_s": 2.0, "home_mm": -149.0,
                "final_mm": -145.0, "accel_mm_s2": 500.0},
          "y": {"direction": 1, "search_mm_s": 20.0, "latch_mm_s": 2.0, "home_mm": 149.0,
                "final_mm": 145.0, "accel_mm_s2": 500.0}}
# A short table (40 mm of travel: a missing switch is given up after 44 mm, in half a
# second at 100 mm/s).
SHORT = {"x": {"direction": -1, "search_mm_s": 100.0, "latch_mm_s": 5.0, "home_mm": -19.0,
               "final_mm": -15.0, "accel_mm_s2": 2000.0},
         "y": {"direction": 1, "search_mm_s": 100.0, "latch_mm_s": 5.0, "home_mm": 19.0,
               "final_mm": 15.0, "accel_mm_s2": 2000.0}}


def homing_config(base: str, folder: Path, homing: dict[str, dict[str, Any]] | None = None,
                  travel_mm: list[float] | None = None,
                  **changes: Any) -> tuple[MachineConfig, Path]:
    """config/<base>.yaml with homing sections (changes apply to every axis), written to
    folder so that a simulated peer can read the same file; (config, path)."""
    data = yaml.safe_load((REPO / "config" / f"{base}.yaml").read_text())
    homing = homing or (SHORT if travel_mm is not None else HOMING)
    for name, axis in data["axes"].items():
        axis["homing"] = dict(homing[name]) | changes
        if travel_mm is not None:
            axis["travel_mm"] = list(travel_mm)
    path = folder / f"{base}_homing.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(str(path)), path


@contextmanager
def peer(backend: str, config: Path | None = None,
         *options: str) -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    """`cncctl simdrive BACKEND` in its own process; yields (process, device path); always
    killed by its pid and reaped."""
    args = [*CLI, "simdrive", backend]
    if config is not None:
        args += ["--config", str(config)]
    for option in options:
        args += ["--option", option]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0,
                            cwd=REPO)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready, "simdrive printed no device path within 20 s"
        path = proc.stdout.readline().decode().strip()
        assert path.startswith("/dev/"), (path, proc.stderr.read() if proc.poll() else "")
        yield proc, path
    finally:
        proc.kill()
        proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()
