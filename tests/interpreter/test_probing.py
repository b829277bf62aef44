"""G38.2-G38.5 in the interpreter (LinuxCNC's straight probe): the checks, the ProbeBlock, the
barrier a probe is to planning, reading on from a result with #5061-#5063 and #5070 set, and
the generator planning a probe move on its own, from rest to rest."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from daemon_helpers import CNCCTL, REPO
from nc_helpers import XYZ_MILL, blocks_of

from controller.blocks import LineBlock, PathMode, ProbeBlock
from controller.config import load_config
from controller.errors import NcError
from controller.generator.plan import plan_program
from controller.interpreter.program import read_program
from controller.offsets import ProgramOffsets
from controller.operator.check_cmd import check_program
from controller.probe import ProbeResult, ProbeResults

PROGRAM = ("G21 G90 G0 X10 Y10 Z5\nG10 L2 P1 X10 Y10\nF100\nG38.2 Z-10\nG91 G0 Z2\n"
           "G90 G38.3 X20\nG0 X0\nM2\n")


def read(tmp_path: Path, text: str, probes: ProbeResults | None = None) -> list:
    path = tmp_path / "p.nc"
    path.write_text(text)
    track = ProgramOffsets(probes=probes or ProbeResults())
    return list(read_program(str(path), XYZ_MILL, track=track))


def test_a_probe_is_a_probe_block_with_linuxcnc_semantics(tmp_path: Path) -> None:
    b = read(tmp_path, PROGRAM)
    probes = [x for x in b if isinstance(x, ProbeBlock)]
    assert [(p.code, p.start, p.end, p.toward, p.error_on_miss) for p in probes] == [
        ("G38.2", (10, 10, 5), (10, 10, -10), True, True),
        ("G38.3", (10, 10, -8), (30, 10, -8), True, False)]
    assert probes[0].feed_mm_s == pytest.approx(100 / 60)
    line = probes[0].as_line()
    assert isinstance(line, LineBlock) and line.path.mode is PathMode.EXACT_STOP


def test_check_reads_on_as_if_each_probe_went_the_whole_way(tmp_path: Path) -> None:
    probes = ProbeResults()
    b = read(tmp_path, PROGRAM, probes)
    assert b[-3].end == (30, 10, -8) and b[-2].end == (10, 10, -8)  # G0 X0 is machine X10
    # #5061-#5063: the last probe's point in the program's frame (G54 at X10 Y10), #5070
    assert probes.parameters == {5061: 20.0, 5062: 0.0, 5063: -8.0, 5070: 1.0}
    assert probes.stopped_at is None


def test_a_run_reads_no_further_than_a_probe_without_its_result(tmp_path: Path) -> None:
    probes = ProbeResults(barrier=True)
    b = read(tmp_path, PROGRAM, probes)
    assert isinstance(b[-1], ProbeBlock) and b[-1].source.first_line == 4
    assert probes.stopped_at == 4
    # its result known: on from where the machine stopped, to the next probe
    probes = ProbeResults([ProbeResult(4, True, (10, 10, -2.5), (10, 10, -2.6))],
                          barrier=True)
    b = read(tmp_path, PROGRAM, probes)
    assert b[-2].end == pytest.approx((10, 10, -0.6))  # G91 G0 Z2 from the stop point
    assert isinstance(b[-1], ProbeBlock) and b[-1].start == b[-2].end
    assert probes.parameters == {5061: 0.0, 5062: 0.0, 5063: -2.5, 5070: 1.0}
    assert probes.stopped_at == 6


def test_g38_2_without_contact_is_an_error_g38_3_goes_on(tmp_path: Path) -> None:
    missed = ProbeResult(4, False, (10, 10, -10), (10, 10, -10))
    with pytest.raises(NcError) as err:
        read(tmp_path, PROGRAM, ProbeResults([missed], barrier=True))
    assert err.value.line == 4 and "without making contact" in err.value.message
    first = ProbeResult(4, True, (10, 10, -10), (10, 10, -10))
    probes = ProbeResults([first, ProbeResult(6, False, (30, 10, -8), (30, 10, -8))])
    read(tmp_path, PROGRAM, probes)
    assert probes.parameters[5070] == 0.0


LOOP = ("G21 G90 G0 X0 Y0 Z5\nF100\no1 repeat [3]\nG38.2 Z-10\nG91 G0 Z2 X10\nG90\n"
        "o1 endrepeat\nG0 Z20\nM2\n")


def test_a_probe_line_run_again_in_a_loop_has_a_result_per_pass(tmp_path: Path) -> None:
    """Results go by the order the probes ran: a stretch yields from after the last one."""
    tripped = [ProbeResult(4, True, (10.0 * k, 0, -1.0 * k), (10.0 * k, 0, -1.0 * k - 0.1))
               for k in range(3)]
    probes = ProbeResults(tripped[:1], barrier=True, resume_after=1)
    b = read(tmp_path, LOOP, probes)
    # from where the first probe stopped: Z2 up and X10 along, then the second pass's probe
    assert b[0].start == pytest.approx((0, 0, -0.1)) and b[0].end == pytest.approx((10, 0, 1.9))
    assert isinstance(b[-1], ProbeBlock) and b[-1].start == b[0].end
    assert probes.stopped_at == 4 and probes.ran == 2
    assert probes.parameters[5063] == -0.0  # the first pass's trip
    probes = ProbeResults(tripped, barrier=True, resume_after=3)
    b = read(tmp_path, LOOP, probes)
    assert probes.stopped_at is None and probes.ran == 3
    assert [blk.end for blk in b if isinstance(blk, LineBlock)][-1][2] == 20.0


ZERO_LENGTH = ("G21 G90 G10 L2 P1 X10 Y10\nG54 G0 X1 Y2 Z5\nF100\nG38.5 Z5\nG38.3 X1 Y2\n"
               "G38.2 Z-10\nG0 Z5\nM2\n")


def test_a_zero_length_g38_3_or_g38_5_ends_at_once_without_contact(tmp_path: Path) -> None:
    """smartprobe.ngc's G38.5 at its safe height: no move, #5070 = 0, #5061-#5063 where the
    machine stands; it takes no result of the machine's (the next probe takes the first)."""
    probes = ProbeResults(barrier=True)
    b = read(tmp_path, ZERO_LENGTH, probes)
    assert [x.source.first_line for x in b if isinstance(x, ProbeBlock)] == [6]
    assert probes.stopped_at == 6 and probes.ran == 1
    probes = ProbeResults(barrier=True)
    read(tmp_path, ZERO_LENGTH.replace("G38.2 Z-10\n", ""), probes)
    assert probes.parameters == {5061: 1.0, 5062: 2.0, 5063: 5.0, 5070: 0.0}
    first = ProbeResult(6, True, (11, 12, -1), (11, 12, -1.1))
    probes = ProbeResults([first], barrier=True)
    b = read(tmp_path, ZERO_LENGTH, probes)
    last = [x for x in b if isinstance(x, LineBlock)][-1]
    assert last.end == pytest.approx((11, 12, 5)) and probes.parameters[5070] == 1.0


@pytest.mark.parametrize(("text", "says"), [
    ("G38.2 Z-5\n", "no feed rate"),
    ("F100 G38.2\n", "needs an axis word"),
    ("F100 G38.4 Z0\n", "zero length cannot lose contact"),
    ("F100 G38.2 X1\n", "zero length cannot make contact"),
    ("F100 G38.2 Z-5 G0\n", "both in the motion modal group"),
])
def test_bad_probes_are_errors_naming_the_line(tmp_path: Path, text: str, says: str) -> None:
    with pytest.raises(NcError) as err:
        blocks_of(tmp_path, "G0 X1\n" + text, XYZ_MILL)
    assert err.value.line == 2 and says in err.value.message


def test_the_generator_plans_a_probe_move_to_rest_on_its_own(tmp_path: Path) -> None:
    b = read(tmp_path, "G21 G90 F600\nG1 X5\nG38.2 Z-4\nG1 X10\n")
    steps = list(plan_program(b, XYZ_MILL))
    rows = np.vstack([s.chunk.pos_mm for s in steps])
    feed = np.concatenate([s.chunk.feed_mm_s for s in steps])
    lines = np.concatenate([s.chunk.line for s in steps])
    probe = lines == 3
    assert rows[probe][-1].tolist() == [5.0, 0.0, -4.0]
    assert feed[probe][0] < 1.0 and feed[probe][-1] < 1e-6  # from rest, to rest
    assert np.all(rows[probe][:, 0] == 5.0)  # straight down: nothing blended into it


def test_check_accepts_a_probe_and_checks_its_whole_move_against_travel(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    path.write_text("F100\nG38.2 Z-150\n")
    with pytest.raises(NcError) as err:
        check_program(str(path), XYZ_MILL)
    assert err.value.line == 2 and "Z travel limit exceeded" in err.value.message
    path.write_text("F100\nG38.2 Z-15\nG0 Z5\nM2\n")
    assert check_program(str(path), XYZ_MILL).blocks["ProbeBlock"] == 1


def test_a_run_with_a_probe_is_refused_before_any_motion(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    path.write_text("G0 X5\nF100\nG38.2 Z-15\nM2\n")
    done = subprocess.run([*CNCCTL, "run", str(path), "--virtual-time", "--config",
                           str(REPO / "config" / "xyz_mill.yaml")], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2 and f"{path}:3:1: error: G38.2: probing is checked" \
        in done.stderr
    assert load_config(str(REPO / "config" / "xyz_mill.yaml")).has_axis("z")
