"""M70-M73 (save, forget, restore the modal state; restore at a subroutine's return) and the
read-only system parameters (#5400, #5420-#5428, #<_x>, #<_feed>, ...)."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import XYZ_MILL, blocks_of

from controller.blocks import LineBlock, OutputBlock
from controller.errors import NcError


def lines(tmp_path: Path, text: str) -> list[LineBlock]:
    return [b for b in blocks_of(tmp_path, text, XYZ_MILL) if isinstance(b, LineBlock)]


def test_m72_restores_units_distance_mode_and_feed(tmp_path: Path) -> None:
    text = "G21 G90 F600\nM70\nG20 G91 F5\nG1 X1\nM72\nG1 X5\nM2\n"
    first, second = lines(tmp_path, text)
    assert first.end[0] == pytest.approx(25.4) and first.feed_mm_s == pytest.approx(5 * 25.4 / 60)
    assert second.end[0] == pytest.approx(5.0) and second.feed_mm_s == pytest.approx(10.0)


def test_m73_restores_at_endsub_and_return_and_m72_needs_a_save(tmp_path: Path) -> None:
    text = (
        "G21 G90 F600\no<s> sub\nM73\nG20 G91 F10\nG1 X1\no1 if [#1 GT 0]\no<s> return\n"
        "o1 endif\no<s> endsub\no<s> call [0]\nG1 X3\no<s> call [1]\nG1 X30\nM2\n"
    )
    moves = lines(tmp_path, text)
    assert [round(b.end[0], 6) for b in moves] == [25.4, 3.0, 28.4, 30.0]
    assert moves[1].feed_mm_s == pytest.approx(10.0) and moves[3].feed_mm_s == pytest.approx(10.0)
    with pytest.raises(NcError, match="M72: no state saved by M70 or M73 at this call level"):
        blocks_of(tmp_path, "G21\nM70\nM71\nM72\nM2\n", XYZ_MILL)


def test_m72_sets_the_spindle_and_coolant_back_as_an_output_block(tmp_path: Path) -> None:
    text = "G21\nM3 S1000 M8\nM70\nM5 M9\nM72\nM2\n"
    outs = [b for b in blocks_of(tmp_path, text, XYZ_MILL) if isinstance(b, OutputBlock)]
    restored = {c.name: c.value for c in outs[2].changes}
    assert outs[2].source.first_line == 5
    assert restored["spindle"] == "cw" and restored["coolant_flood"] is True


def test_m72_selects_the_saved_work_system_again(tmp_path: Path) -> None:
    text = "G21\nG10 L2 P2 X100\nM70\nG55\nG0 X1\nM72\nG0 X1\nM2\n"
    assert [b.end[0] for b in lines(tmp_path, text)] == [101.0, 1.0]


def test_position_and_mode_parameters_read_the_state(tmp_path: Path) -> None:
    text = (
        "G21 G90\nG10 L2 P1 X10\nG0 X3 Y4 Z5\nG1 X[#5420 + #<_y>] Y[#<_absolute> + "
        "#<_imperial>] Z#<_call_level> F[#<_coord_system>]\nM2\n"
    )
    move = lines(tmp_path, text)[-1]
    assert move.end == pytest.approx((10 + 3 + 4, 1.0, 0.0))
    assert move.feed_mm_s == pytest.approx(540 / 60)


def test_system_parameters_are_read_only(tmp_path: Path) -> None:
    with pytest.raises(NcError, match=r"#<_x> is read-only"):
        blocks_of(tmp_path, "#<_x> = 2\nM2\n", XYZ_MILL)
    with pytest.raises(NcError, match=r"out of range|read-only"):
        blocks_of(tmp_path, "#5420 = 2\nM2\n", XYZ_MILL)
