"""Tiny test-only reader of the G6.2 NURBS programs in nc_programs/ (no interpreter needed)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from controller.nurbs import Nurbs

REPO = Path(__file__).resolve().parents[1]
_WORD = re.compile(r"([XYRKP])\s*(-?\d+(?:\.\d*)?)")


def read_g62(path: str | Path) -> Nurbs:
    """The first G6.2 block: X Y R K lines then trailing 'G6.2 K' lines; P is the order."""
    pts: list[tuple[float, float]] = []
    weights: list[float] = []
    knots: list[float] = []
    order = 0
    for raw in Path(path).read_text().splitlines():
        line = raw.split("(")[0].strip()
        words = dict(_WORD.findall(line))
        if "X" in words and "K" in words:
            pts.append((float(words["X"]), float(words["Y"])))
            weights.append(float(words.get("R", 1.0)))
            knots.append(float(words["K"]))
            order = int(float(words["P"])) if "P" in words else order
        elif line.startswith("G6.2") and "K" in words:
            knots.append(float(words["K"]))
    return Nurbs(order - 1, np.array(knots), np.array(pts), np.array(weights))


def program(name: str) -> Path:
    return REPO / "nc_programs" / name
