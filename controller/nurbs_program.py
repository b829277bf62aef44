"""The NURBS blocks of a G-code program as Nurbs curves (for benches, tests and tools)."""

from __future__ import annotations

from controller.blocks import NurbsBlock
from controller.config import MachineConfig, load_config
from controller.nurbs import Nurbs


def program_nurbs(path: str, config: MachineConfig | None = None) -> list[Nurbs]:
    """Every NURBS block of the program, in order (default machine config if none given)."""
    from controller.interpreter import read_program  # late: the interpreter is a heavier import

    cfg = config if config is not None else load_config(None)
    return [Nurbs.from_block(b) for b in read_program(path, cfg) if isinstance(b, NurbsBlock)]
