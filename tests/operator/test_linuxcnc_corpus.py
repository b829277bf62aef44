"""Every XY program of LinuxCNC (tests/data/linuxcnc, GPL-2.0) checks clean on the mill."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import XYZ_MILL

from controller.operator.check_cmd import check_program

DATA = Path(__file__).resolve().parents[1] / "data" / "linuxcnc"
PROGRAMS = sorted(DATA.rglob("*.ngc"))


def test_corpus_and_licence_note_are_there() -> None:
    assert len(PROGRAMS) == 40
    assert "GPL-2.0" in (DATA / "LICENSE-NOTE.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("path", PROGRAMS, ids=[str(p.relative_to(DATA)) for p in PROGRAMS])
def test_program_checks_clean_on_the_mill(path: Path) -> None:
    summary = check_program(str(path), XYZ_MILL)
    assert summary.path_length_mm > 0
    assert sum(summary.blocks.values()) > 0
