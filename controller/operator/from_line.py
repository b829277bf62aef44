"""Run from line: the approach from where the machine stands to where the program is at line N."""

from __future__ import annotations

from controller.config import MachineConfig

APPROACH_FEED_SHARE = 0.5  # of the maximum feed: a visible, interruptible move


def approach_program(config: MachineConfig, here_mm: tuple[float, float, float],
                     target_mm: tuple[float, float, float]) -> str:
    """G-code in machine coordinates (no offsets in force) for the approach: on a machine
    with Z, up to the higher of the two heights first, then across in XY, then down; on an XY
    table one straight move. Empty when the machine is already there (within a micrometre)."""
    feed = APPROACH_FEED_SHARE * config.interpolator.max_feed_mm_s * 60.0
    moves: list[str] = []
    x, y, z = target_mm
    if config.has_axis("z"):
        top = max(here_mm[2], z)
        if top - here_mm[2] > 1e-3:
            moves.append(f"G1 Z{top:.4f}")
        if max(abs(x - here_mm[0]), abs(y - here_mm[1])) > 1e-3:
            moves.append(f"G1 X{x:.4f} Y{y:.4f}")
        if top - z > 1e-3:
            moves.append(f"G1 Z{z:.4f}")
    elif max(abs(x - here_mm[0]), abs(y - here_mm[1])) > 1e-3:
        moves.append(f"G1 X{x:.4f} Y{y:.4f}")
    if not moves:
        return ""
    return f"G21 G90 G61 F{feed:.1f}\n" + "\n".join(moves) + "\nM2\n"
