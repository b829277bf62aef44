"""LinuxCNC's rs274 as the oracle: the programs of tests/data read to the same moves (to 1 um)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
from nc_helpers import REPO, XYZ_MILL


def _oracle():  # noqa: ANN202
    spec = importlib.util.spec_from_file_location("bench_rs274_oracle",
                                                  REPO / "bench" / "rs274_oracle.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


ORACLE = _oracle()
RS274 = ORACLE.find_rs274()
needs_rs274 = pytest.mark.skipif(
    RS274 is None, reason="LinuxCNC's rs274 is not installed (Debian: apt-get install "
                          "linuxcnc-uspace); the comparison with it cannot run here")
DATA = REPO / "tests" / "data"
SAME = sorted((DATA / "oracle").glob("*.ngc")) + [
    p for p in sorted((DATA / "cam").rglob("*")) if p.suffix in (".ngc", ".gcode")
    and p.name != "cutout.ngc"]


@needs_rs274
@pytest.mark.parametrize("path", SAME, ids=[str(p.relative_to(DATA)) for p in SAME])
def test_same_moves_as_linuxcnc(path: Path, tmp_path: Path) -> None:
    row = ORACLE.compare(str(path), XYZ_MILL, RS274, str(tmp_path))
    if row["status"] == "ours-only" and "no percent sign or program end" in row["rs274"]:
        # A post for another controller ends without M2 (we warn, rs274 refuses): the moves
        # are compared on the program with its M2.
        ended = tmp_path / path.name
        ended.write_text(path.read_text() + "\nM2\n")
        row = ORACLE.compare(str(ended), XYZ_MILL, RS274, str(tmp_path))
    assert row["status"] == "same", row


@needs_rs274
def test_a_program_linuxcnc_refuses_is_accepted_with_a_warning(tmp_path: Path) -> None:
    path = DATA / "cam" / "camotics" / "cutout.ngc"
    row = ORACLE.compare(str(path), XYZ_MILL, RS274, str(tmp_path))
    assert row["status"] == "ours-only" and "no percent sign or program end" in row["rs274"]
    from controller.interpreter.program import read_program
    from controller.offsets import ProgramOffsets

    track = ProgramOffsets()
    for _ in read_program(str(path), XYZ_MILL, track=track):
        pass
    assert any("without M2, M30 or a closing %" in w for w in track.warnings)


@needs_rs274
def test_the_comparison_finds_a_two_micrometre_difference(tmp_path: Path) -> None:
    """The oracle can fail: rs274 reads one program, we read it with one point moved 2 um."""
    text = (DATA / "oracle" / "cycles.ngc").read_text()
    moved = tmp_path / "moved.ngc"
    moved.write_text(text.replace("G98 G81 X10 Y10", "G98 G81 X10.002 Y10"))
    theirs = ORACLE.run_rs274(RS274, str(DATA / "oracle" / "cycles.ngc"), str(tmp_path))
    ours = ORACLE.run_ours(str(moved), XYZ_MILL)
    assert theirs.accepted and ours.accepted
    assert "end" in ORACLE.first_difference(theirs.moves, ours.moves)
    same = ORACLE.run_ours(str(DATA / "oracle" / "cycles.ngc"), XYZ_MILL)
    assert ORACLE.first_difference(theirs.moves, same.moves) is None


@needs_rs274
def test_g5_1_splines_end_where_linuxcnc_ends_them(tmp_path: Path) -> None:
    """rs274 prints no spline geometry: every other move, among them G91 moves and offsets and
    a G20 after the splines, shows where each side ends each G5.1 (control points: the unit
    tests of test_polar_splines.py)."""
    row = ORACLE.compare(str(DATA / "oracle" / "nurbs" / "g5_1.ngc"), XYZ_MILL, RS274,
                         str(tmp_path))
    assert row["status"] == "not-compared" and row["why"].startswith("NURBS: 5 NURBS"), row


@needs_rs274
def test_the_comparison_finds_a_spline_that_ends_elsewhere(tmp_path: Path) -> None:
    """The NURBS comparison can fail: a G91 G5.1 ends 2 um further in our copy (the G91 move
    after it shows where it ended)."""
    text = (DATA / "oracle" / "nurbs" / "g5_1.ngc").read_text()
    moved = tmp_path / "moved.ngc"
    moved.write_text(text.replace("G91 G5.1 X-10 Y10", "G91 G5.1 X-9.998 Y10"))
    theirs = ORACLE.run_rs274(RS274, str(DATA / "oracle" / "nurbs" / "g5_1.ngc"),
                              str(tmp_path))
    ours = ORACLE.run_ours(str(moved), XYZ_MILL)
    assert theirs.accepted and ours.accepted
    assert "end" in ORACLE.first_difference(theirs.moves, ours.moves)


def test_a_zero_length_move_after_a_nurbs_is_passed_over_only_at_our_nurbs_end() -> None:
    """rs274 prints the G0 to where its NURBS ended; we drop it, being there already."""
    nan = (float("nan"),) * 3
    theirs = [ORACLE.Move("NURBS", nan, 1.0), ORACLE.Move("G0", (1.0, 1.0, 0.0))]
    assert ORACLE.first_difference(theirs, [ORACLE.Move("NURBS", (1.0, 1.0, 0.0), 1.0)]) is None
    elsewhere = [ORACLE.Move("NURBS", (1.0, 1.002, 0.0), 1.0)]
    assert "more moves" in ORACLE.first_difference(theirs, elsewhere)


@needs_rs274
def test_a_g5_2_program_reads_to_the_same_moves_around_its_nurbs(tmp_path: Path) -> None:
    path = DATA / "linuxcnc" / "nurbs" / "G5" / "Curva_Delfino__1_1_G5.ngc"
    row = ORACLE.compare(str(path), XYZ_MILL, RS274, str(tmp_path))
    assert row["status"] == "not-compared" and row["why"].startswith("NURBS: 1 NURBS"), row


def test_an_offset_is_read_in_the_units_it_was_printed_in() -> None:
    """G10 in mm, then G20: rs274 does not print the offset again in inches."""
    text = "\n".join([
        "    1 N..... USE_LENGTH_UNITS(CANON_UNITS_MM)",
        "    2 N..... SET_G5X_OFFSET(2, 5.0000, -5.0000, 0.0000, 0.0000, 0.0000, 0.0000)",
        "    3 N..... USE_LENGTH_UNITS(CANON_UNITS_INCHES)",
        "    4 N..... STRAIGHT_TRAVERSE(1.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)",
    ])
    (move,) = ORACLE.parse_calls(text).moves
    assert move.end_mm == pytest.approx((25.4 + 5.0, -5.0, 0.0))


def test_canonical_calls_are_read_in_machine_mm() -> None:
    """rs274 prints the work frame in program units; offsets and inches are undone."""
    text = "\n".join([
        "    1 N..... USE_LENGTH_UNITS(CANON_UNITS_INCHES)",
        "    2 N..... SET_G5X_OFFSET(2, 1.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)",
        "    3 N..... SET_G92_OFFSET(0.0000, 0.5000, 0.0000, 0.0000, 0.0000, 0.0000)",
        "    4 N..... SET_FEED_RATE(10.0000)",
        "    5 N..... STRAIGHT_FEED(1.0000, 1.0000, 0.0000, 0.0000, 0.0000, 0.0000)",
        "    6 N..... STRAIGHT_FEED(1.0000, 1.0000, 0.0000, 0.0000, 0.0000, 0.0000)",
        "    7 N..... ARC_FEED(2.0000, 1.0000, 1.5000, 1.0000, -1, 0.0000, 0.0, 0.0, 0.0)",
    ])
    moves = ORACLE.parse_calls(text).moves
    assert len(moves) == 2  # the zero-length feed is dropped
    assert moves[0].end_mm == pytest.approx((50.8, 38.1, 0.0))
    assert moves[0].feed_mm_s == pytest.approx(10 * 25.4 / 60)
    assert moves[1].kind == "ARC" and moves[1].rotation == -1
    assert moves[1].centre_mm == pytest.approx((63.5, 38.1))


def _random_expression(rng, depth: int = 0) -> str:  # noqa: ANN001
    """A random LinuxCNC expression of small numbers, operators and functions."""
    if depth > 2 or rng.random() < 0.3:
        return rng.choice(["1", "2", "3", "0.5", "7", "-4", "2.25", "10", "#1", "#<_k>"])
    kind = rng.random()
    if kind < 0.2:
        name = rng.choice(["ABS", "COS", "SIN", "FIX", "FUP", "ROUND", "EXP"])
        arg = _random_expression(rng, depth + 1)
        return f"{name}[{arg}]" if name != "EXP" else f"EXP[[{arg}] / 10]"
    if kind < 0.25:
        return f"ATAN[{_random_expression(rng, depth + 1)}]/[{_random_expression(rng, depth + 1)}]"
    terms = [_random_expression(rng, depth + 1) for _ in range(rng.randint(2, 4))]
    ops = ["+", "-", "*", "/", "MOD", "**", "EQ", "NE", "GT", "GE", "LT", "LE", "AND", "OR",
           "XOR"]
    text = terms[0]
    for term in terms[1:]:
        text += f" {rng.choice(ops)} {term}"
    return f"[{text}]"


@needs_rs274
def test_random_expressions_evaluate_as_in_linuxcnc(tmp_path: Path) -> None:
    """Operators, precedence and functions against rs274 itself: 300 random expressions, each
    the X of a move (only those our reader evaluates to a value within the travel)."""
    import random

    from controller.interpreter.expr import ExprError, Reader
    from controller.interpreter.params import Parameters

    rng = random.Random(34)
    params = Parameters()
    params.set(1, 3.0)
    params.set_named("_k", -1.5)
    lines = ["G21 G90 F600", "#1 = 3", "#<_k> = -1.5"]
    while len(lines) < 303:
        text = _random_expression(rng)
        try:
            value = Reader(text.upper(), params).value(0)[0]
        except (ExprError, OverflowError, ZeroDivisionError):
            continue
        if abs(value) < 400 and text.startswith("[") and len(text) < 200:  # rs274: 256
            lines.append(f"G1 X{text} Y{len(lines) % 7}")
    lines.append("M2")
    path = tmp_path / "expressions.ngc"
    path.write_text("\n".join(lines) + "\n")
    row = ORACLE.compare(str(path), XYZ_MILL, RS274, str(tmp_path))
    assert row["status"] == "same", row
    assert int(row["why"].split()[0]) > 250  # moves compared (a few repeat the point before)


@needs_rs274
def test_a_program_that_probes_is_compared_up_to_its_first_probe(tmp_path: Path) -> None:
    """rs274 standalone takes a probe to trip 0.01 in short of its end, our check at its end:
    a G92 there then moves what follows (differing by design); the moves before the probe must
    be the same."""
    path = tmp_path / "probe.ngc"
    path.write_text("G21 G90 F100\nG0 X1 Y2\nG1 Z-1\nG38.2 Z-5\nG92 Z0\nG0 Z1\nM2\n")
    row = ORACLE.compare(str(path), XYZ_MILL, RS274, str(tmp_path))
    assert row["status"] == "not-compared", row
    assert row["why"] == "probe: the 2 moves before the first probe are the same"
