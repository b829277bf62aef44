"""The blocks a check keeps for simulate: the same blocks again, lines kept as numbers."""

from __future__ import annotations

from pathlib import Path

from controller.config import load_config
from controller.interpreter.program import read_program
from controller.operator.kept_blocks import KeptBlocks

PROGRAM = """G21 G90 G17 G64 F600
G1 X1 Y0
G1 X1 Y1
G0 X2 Y2
G1 X3 Y2 F900
G64 P0.01
G1 X3 Y3
G2 X4 Y4 I1 J0
G1 X5 Y4
G4 P0.1
G1 X6 Y-0.5
G1 X-0 Y0
M2
"""


def _blocks(tmp_path: Path) -> list:
    prog = tmp_path / "p.nc"
    prog.write_text(PROGRAM)
    return list(read_program(str(prog), load_config("xy_table")))


def test_the_kept_blocks_are_the_blocks_appended_in_order(tmp_path: Path) -> None:
    blocks = _blocks(tmp_path)
    kept = KeptBlocks(100, 100, 1)  # lines but the first as numbers
    for b in blocks:
        kept.append(b)
    assert not kept.full and len(kept) == len(blocks)
    assert list(kept) == blocks
    assert list(kept) == blocks  # read again (simulate --compare plans it four times)
    again = list(kept)
    for before, after in zip(again, again[1:], strict=False):
        if hasattr(before, "end") and hasattr(after, "start"):
            assert after.start == before.end


def test_full_once_past_either_limit(tmp_path: Path) -> None:
    blocks = _blocks(tmp_path)
    n_lines = sum(type(b).__name__ == "LineBlock" for b in blocks)
    n_other = len(blocks) - n_lines
    for max_blocks, max_lines, full in (
        (n_other, n_lines, False),
        (n_other - 1, n_lines, True),
        (n_other, n_lines - 1, True),
    ):
        kept = KeptBlocks(max_blocks, max_lines, 1)
        for b in blocks:
            kept.append(b)
        assert kept.full == full
