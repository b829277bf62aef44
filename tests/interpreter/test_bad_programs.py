"""LinuxCNC tests/interp/bad style: every program in bad/ fails with the message on its first line.

The first line is `; LINE:COL: error: MESSAGE`, the path-independent part of what `cncctl check`
prints. Files named `mill-*` are checked on config xyz_mill, the others on xy_table.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import XY_TABLE, XYZ_MILL

from controller.errors import NcError
from controller.operator.check_cmd import check_program

BAD = sorted((Path(__file__).parent / "bad").glob("*.ngc"))


def test_there_are_bad_programs() -> None:
    assert len(BAD) >= 80


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_bad_program_gives_its_exact_message(path: Path) -> None:
    with path.open(encoding="utf-8", errors="replace") as f:
        expected = f.readline().rstrip("\n").removeprefix("; ")
    config = XYZ_MILL if path.name.startswith("mill-") else XY_TABLE
    with pytest.raises(NcError) as info:
        check_program(str(path), config)
    assert info.value.format() == f"{path}:{expected}"
