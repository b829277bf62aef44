"""A G1 line that would take more than a day at its feed is refused, one just under is not."""

from __future__ import annotations

from pathlib import Path

import pytest

from controller.config import load_config
from controller.errors import NcError
from controller.interpreter.moves import MAX_BLOCK_S
from controller.interpreter.program import read_program


def _read(tmp_path: Path, text: str) -> list:
    prog = tmp_path / "p.nc"
    prog.write_text(text)
    return list(read_program(str(prog), load_config("xy_table")))


@pytest.mark.parametrize("share", [0.999, 1.001])
def test_a_line_longer_than_a_day_at_its_feed_is_refused(tmp_path: Path, share: float) -> None:
    feed_mm_min = 1.0  # the lowest feed the interpreter accepts
    length_mm = share * MAX_BLOCK_S * feed_mm_min / 60.0
    text = f"G21 G90 G17\nG1 X{length_mm:.4f} F{feed_mm_min}\nM2\n"
    if share < 1.0:
        assert len(_read(tmp_path, text)) >= 1
        return
    with pytest.raises(NcError, match="in one block"):
        _read(tmp_path, text)
