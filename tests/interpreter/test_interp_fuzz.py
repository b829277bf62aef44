"""Property tests: whatever the bytes, the interpreter and `check` raise only NcError."""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE, XYZ_MILL

from controller.errors import NcError
from controller.interpreter.program import position_at_line, read_program
from controller.operator.check_cmd import check_program

REPO = Path(__file__).resolve().parents[2]
SEEDS = [REPO / "nc_programs" / n for n in ("naca2415.nc", "arcs.nc", "nurbs_g52.nc",
                                            "g64_corners.nc")]
SEEDS += [REPO / "tests/data/linuxcnc" / n for n in ("plain/cds.ngc",
                                                      "nurbs/G6/Curva_Stella__1_2-xy.ngc")]
SEED_LINES = [p.read_bytes().splitlines(keepends=True) for p in SEEDS]
GCODE_BYTES = b"GMXYZIJKRPQLFSTN0123456789.-+ ()%;/#=\n\t[]EOg" + bytes([0, 255, 128])
FUZZ = settings(max_examples=120, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])


def _check_only_nc_errors(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.nc"
        path.write_bytes(data)
        for config in (XY_TABLE, XYZ_MILL):
            try:
                check_program(str(path), config)
            except NcError as exc:
                assert exc.line >= 0 and exc.col >= 0 and exc.message
                assert exc.format().startswith(f"{path}:{exc.line}:{exc.col}: error: ")


@FUZZ
@given(st.binary(max_size=400))
def test_random_bytes(data: bytes) -> None:
    _check_only_nc_errors(data)


@FUZZ
@given(st.lists(st.sampled_from(list(GCODE_BYTES)), max_size=300))
def test_random_gcode_alphabet(chars: list[int]) -> None:
    _check_only_nc_errors(bytes(chars))


_mutation = st.tuples(st.sampled_from(["delete", "insert", "replace", "dup", "drop"]),
                      st.integers(0, 10**6), st.integers(0, 10**6),
                      st.sampled_from(list(GCODE_BYTES)))


@FUZZ
@given(st.integers(0, len(SEEDS) - 1), st.lists(_mutation, min_size=1, max_size=8))
def test_mutated_real_programs(seed: int, mutations: list[tuple[str, int, int, int]]) -> None:
    lines = list(SEED_LINES[seed])
    for op, i, j, byte in mutations:
        k = i % len(lines)
        line = lines[k]
        pos = j % (len(line) + 1)
        if op == "delete":
            lines[k] = line[:pos] + line[pos + 1:]
        elif op == "insert":
            lines[k] = line[:pos] + bytes([byte]) + line[pos:]
        elif op == "replace":
            lines[k] = line[:pos] + bytes([byte]) + line[pos + 1:]
        elif op == "dup":
            lines.insert(k, line)
        elif len(lines) > 1:
            del lines[k]
    _check_only_nc_errors(b"".join(lines))


def test_huge_line_and_huge_numbers() -> None:
    _check_only_nc_errors(b"G0 X1\n" + b"9" * 10_000_000 + b"\n")
    _check_only_nc_errors(b"G1 F99999999999999999999 X99999999999999999999.99999999999999999999\n")
    _check_only_nc_errors(b"G0 X1\n(" + b"a" * 10_000_000)


OFFSET_WORDS = ["G10", "L2", "L20", "L1", "P0", "P2", "P7", "P1.5", "R1", "G92", "G92.1",
                "G92.2", "G53", "G54", "G55", "G59", "G0", "G1", "G2", "G91", "G90", "G20",
                "X1", "Y-2", "Z3", "X99999999999999999999", "F100", "I1", "J1", "G5.2", "G5.3",
                "G6.2", "K0", "K1", "M2", "G80", "G4"]


@FUZZ
@given(st.lists(st.lists(st.sampled_from(OFFSET_WORDS), max_size=5).map(" ".join),
                max_size=12), st.integers(-1, 14))
def test_offset_words_and_run_from_line_raise_only_nc_errors(lines: list[str], n: int) -> None:
    data = ("\n".join(lines) + "\n").encode()
    _check_only_nc_errors(data)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.nc"
        path.write_bytes(data)
        for config in (XY_TABLE, XYZ_MILL):
            try:
                list(read_program(str(path), config, from_line=n))
                position_at_line(str(path), config, n)
            except NcError as exc:
                assert exc.format().startswith(f"{path}:{exc.line}:{exc.col}: error: ")
