"""M98/M99 numbered programs (LinuxCNC 2.9) and Mach3's G31, #2000-#2002 and M40/M41 probe log."""

from __future__ import annotations

from pathlib import Path

import pytest
from nc_helpers import XY_TABLE, XYZ_MILL, blocks_of

from controller.blocks import ProbeBlock
from controller.config import MachineConfig
from controller.errors import NcError
from controller.interpreter.flow import MAX_CALL_DEPTH
from controller.interpreter.program import read_program
from controller.interpreter.subprograms import MAX_PROGRAM_PASSES
from controller.offsets import ProgramOffsets


def ends(tmp_path: Path, text: str) -> list[tuple[float, ...]]:
    return [
        tuple(b.end)
        for b in blocks_of(tmp_path, text, XYZ_MILL)
        if hasattr(b, "end") and b.end is not None
    ]


def warnings_of(path: Path, config: MachineConfig = XYZ_MILL) -> list[str]:
    track = ProgramOffsets()
    for _ in read_program(str(path), config, track=track):
        pass
    return track.warnings


def test_m99_in_the_main_program_runs_it_again_until_it_ends(tmp_path: Path) -> None:
    """The lines before the first O-word or M98 are read again from the file on each pass;
    the parameters keep their values (LinuxCNC's task seeks back to the first line). xy_table
    keeps LinuxCNC's rule (xyz_mill ends the job there: test_centroid)."""
    text = "G21 G90 F600\n#<_n> = [#<_n> + 1]\nG1 X#<_n>\no1 if [#<_n> GE 4]\nM2\no1 endif\nM99\n"
    path = tmp_path / "p.ngc"
    path.write_text("#<_n> = 0\n" + text)
    # the first line sets the counter again on every pass: that program never ends
    with pytest.raises(NcError) as info:
        list(read_program(str(path), XY_TABLE))
    assert info.value.line == 8 and info.value.word == "M99"
    assert f"did not end within {MAX_PROGRAM_PASSES} passes" in info.value.message
    counted = tmp_path / "q.ngc"
    counted.write_text("o2 if [EXISTS[#<_n>] EQ 0]\n#<_n> = 0\no2 endif\n" + text)
    xs = [b.end[0] for b in read_program(str(counted), XY_TABLE) if hasattr(b, "end")]
    assert xs[:4] == [1.0, 2.0, 3.0, 4.0]
    warned = warnings_of(counted, XY_TABLE)
    assert any(":10: M99: M99 in the main program starts it again" in w for w in warned)


def test_a_numbered_program_repeats_with_l_and_shares_numbered_parameters(tmp_path: Path) -> None:
    text = (
        "G21 G90 F600\n#1 = 0\n#<x> = 5\nM98 P7 L3\nG1 X#1 Y#<x>\nM98 P7 L0\nM98 P8 L0\nM2\n"
        "O7\n#1 = [#1 + 1]\n#<x> = 99\nG1 Y#1\nM99\n"
    )
    assert ends(tmp_path, text) == [
        (0.0, 1.0, 0.0),
        (0.0, 2.0, 0.0),
        (0.0, 3.0, 0.0),
        (3.0, 5.0, 0.0),
    ]


def test_endless_recursion_is_bounded(tmp_path: Path) -> None:
    with pytest.raises(NcError) as info:
        blocks_of(tmp_path, "G21 F600\nM98 P5\nM2\nO5\nG91 G1 X0.001\nM98 P5\nM99\n")
    assert info.value.line == 6 and info.value.word == "M98"
    assert f"nested deeper than {MAX_CALL_DEPTH}" in info.value.message


def test_a_subprogram_called_twice_is_found_again_before_the_call(tmp_path: Path) -> None:
    """Once an M98 has found O5 ahead, later calls go back to it (LinuxCNC remembers it)."""
    text = "G21 F600\nM98 P6\nM2\nO5\nG1 X[#9 + 1]\nM99\nO6\n#9 = 1\nM98 P5\nM98 P5\nM99\n"
    with pytest.raises(NcError) as info:  # O5 stands before the first call to it
        blocks_of(tmp_path, text)
    assert info.value.line == 9 and "stands before, at line 4" in info.value.message
    fine = "G21 F600\n#9 = 1\nM98 P5\nM98 P6\nM2\nO5\n#9 = [#9 + 1]\nG1 X#9\nM99\nO6\nM98 P5\nM99\n"
    assert [b.end[0] for b in blocks_of(tmp_path, fine) if hasattr(b, "end")] == [2.0, 3.0]


def test_g31_is_read_as_g38_2_and_fills_mach3_probe_parameters(tmp_path: Path) -> None:
    path = tmp_path / "mach3.ngc"
    path.write_text(
        "G21 G90 F100\nG0 X3 Y4 Z2\nM40\nG31 Z-1.5 F50\nG1 Z[#2002 + 0.25] "
        "X[#2000 + 1] Y#2001\nM41\nM2\n"
    )
    blocks = list(read_program(str(path), XYZ_MILL))
    probes = [b for b in blocks if isinstance(b, ProbeBlock)]
    assert len(probes) == 1 and probes[0].code == "G38.2"
    assert tuple(probes[0].end) == (3.0, 4.0, -1.5)
    last = [b for b in blocks if hasattr(b, "end") and not isinstance(b, ProbeBlock)][-1]
    assert tuple(last.end) == pytest.approx((4.0, 4.0, -1.25))
    warned = warnings_of(path)
    assert any(":4: G31: Mach3's straight probe, read as G38.2" in w for w in warned)
    assert any(":3: M40: Mach3's 'open the probe log'" in w for w in warned)
    assert any(":6: M41: Mach3's 'close the probe log'" in w for w in warned)


def test_m40_needs_a_g31_outside_comments(tmp_path: Path) -> None:
    with pytest.raises(NcError) as info:
        blocks_of(tmp_path, "G21 F100\n(probe with G31 later)\nM41\nG1 X1\nM2\n", XY_TABLE)
    assert info.value.line == 3 and info.value.word == "M41"
    assert "Fanuc and Haas: a gear range" in info.value.message
