"""Long programs for the tests: bench/long_programs.py's seeded writers, small."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _bench():
    name = "long_programs_bench"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, REPO / "bench" / "long_programs.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def walk(directory: Path, lines: int, seed: int = 19) -> Path:
    """A G1 random walk of `lines` lines of 0.05-0.5 mm (F3500, G64) inside the travel."""
    path = directory / f"walk_{lines}_{seed}.nc"
    _bench().write_walk(path, lines, seed)
    return path


def airfoils(directory: Path, copies: int) -> Path:
    """nc_programs/naca2415.nc's NURBS block `copies` times in a row."""
    path = directory / f"airfoil_x{copies}.nc"
    _bench().write_airfoil(path, copies)
    return path


def bench_module():
    return _bench()
