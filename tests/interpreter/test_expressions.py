"""Parameters and expressions as LinuxCNC reads them: operators, precedence, functions, errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XYZ_MILL, blocks_of

from controller.errors import NcError
from controller.interpreter.expr import ExprError, Reader
from controller.interpreter.params import Parameters


def value(text: str, params: Parameters | None = None) -> float:
    return Reader(text.upper(), params or Parameters()).value(0)[0]


@pytest.mark.parametrize(("text", "expected"), [
    ("[1 + 2 * 3]", 7.0),
    ("[2 ** 3 ** 2]", 64.0),  # left to right within one precedence, as LinuxCNC
    ("[2 * 3 ** 2]", 18.0),
    ("[10 - 4 - 3]", 3.0),
    ("[7 MOD 3]", 1.0),
    ("[-7 MOD 3]", 2.0),  # LinuxCNC's MOD is never negative
    ("[1 + 2 EQ 3]", 1.0),
    ("[1 EQ 1.00001]", 1.0),  # EQ within LinuxCNC's 0.0001
    ("[1 NE 1.001]", 1.0),
    ("[2 GT 1 AND 1 LT 2]", 1.0),
    ("[0 OR 0]", 0.0),
    ("[1 XOR 1]", 0.0),
    ("[3 GE 3]", 1.0), ("[3 LE 2]", 0.0),
    ("ABS[-2.5]", 2.5), ("ACOS[0]", 90.0), ("ASIN[1]", 90.0), ("ATAN[1]/[1]", 45.0),
    ("ATAN[1]/[-1]", 135.0), ("COS[60]", 0.5), ("SIN[30]", 0.5), ("TAN[45]", 1.0),
    ("EXP[0]", 1.0), ("LN[1]", 0.0), ("SQRT[16]", 4.0),
    ("FIX[-1.5]", -2.0), ("FUP[-1.5]", -1.0), ("FIX[1.5]", 1.0), ("FUP[1.2]", 2.0),
    ("ROUND[2.5]", 3.0), ("ROUND[-2.5]", -3.0), ("ROUND[1.4]", 1.0),
    ("-[1 + 1]", -2.0), ("[ [1 + 2] * [3 + 4] ]", 21.0),
    ("[1/4]", 0.25), ("[1.5*2]", 3.0),
])
def test_operators_and_functions(text: str, expected: float) -> None:
    assert value(text) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(("text", "fragment"), [
    ("[1/0]", "division by zero"),
    ("[1 MOD 0]", "division by zero"),
    ("SQRT[-1]", "SQRT of -1"),
    ("LN[0]", "LN of 0"),
    ("ACOS[2]", "ACOS of 2"),
    ("[-8 ** 0.5]", "non-integer power"),
    ("[1 + 2", "missing ']'"),
    ("[1 ? 2]", "binary operator"),
    ("FOO[1]", "unknown function"),
    ("ATAN[1]", "ATAN needs two arguments"),
    ("#<nothing>", "#<nothing> is not set"),
    ("#[1.5]", "not an integer"),
    ("[" * 70 + "1" + "]" * 70, "nested deeper"),
])
def test_errors_name_the_problem(text: str, fragment: str) -> None:
    with pytest.raises(ExprError) as info:
        value(text)
    assert fragment in info.value.message


def test_parameters_numbered_named_global_and_indirect() -> None:
    params = Parameters()
    params.set(1, 2.0)
    params.set(2, 7.0)
    params.set_named("depth", 3.0)
    params.set_named("_safe", 5.0)
    assert value("#1", params) == 2.0
    assert value("##1", params) == 7.0  # #[#1] = #2
    assert value("#[#1 - 1]", params) == 2.0
    assert value("#<Depth>", params) == 3.0  # names ignore case and spaces
    assert value("#< d e p t h >", params) == 3.0
    assert value("[#<_safe> + #<depth>]", params) == 8.0
    assert value("EXISTS[#<depth>]", params) == 1.0
    assert value("EXISTS[#<other>]", params) == 0.0


@settings(max_examples=200, deadline=None)
@given(a=st.integers(-1000, 1000), b=st.integers(-1000, 1000), c=st.integers(1, 1000))
def test_arithmetic_matches_python(a: int, b: int, c: int) -> None:
    assert value(f"[{a} + {b} * {c}]") == a + b * c
    assert value(f"[{a} - {b} / {c}]") == pytest.approx(a - b / c)
    assert value(f"[[{a} + {b}] * {c}]") == (a + b) * c
    assert value(f"[{a} LT {b} OR {b} LT {a}]") == float(a != b)


def test_word_values_are_evaluated_before_the_line_runs(tmp_path: Path) -> None:
    b = blocks_of(tmp_path, "#<x> = 4\n#1 = 0.5\nG1 X [1+2] Y#<x> Z-#1 F[100*6]\n"
                            "G1 X[#<x> * COS[0]] Y[ATAN[1]/[1]]\n", XYZ_MILL)
    assert b[0].end == pytest.approx((3.0, 4.0, -0.5))
    assert b[0].feed_mm_s == pytest.approx(10.0)
    assert b[1].end == pytest.approx((4.0, 45.0, -0.5))


def test_settings_take_effect_after_the_line(tmp_path: Path) -> None:
    # LinuxCNC: every word of a line sees the values from before the line.
    b = blocks_of(tmp_path, "#1 = 1\n#1 = 2 G0 X#1\nG0 Y#1\n")
    assert b[0].end[0] == 1.0 and b[1].end[1] == 2.0


def test_x_bracket_expression_is_not_a_missing_number(tmp_path: Path) -> None:
    (line,) = blocks_of(tmp_path, "G0 X [1+2]\n")
    assert line.end[0] == 3.0
    with pytest.raises(NcError, match="X word without a number"):
        blocks_of(tmp_path, "G0 X Y1\n")


def test_infinite_value_is_refused(tmp_path: Path) -> None:
    with pytest.raises(NcError, match="not finite"):
        blocks_of(tmp_path, "G0 X[10 ** 300 * 10 ** 300]\n")


def test_angles_in_degrees() -> None:
    assert value("SIN[90]") == 1.0
    assert value("ATAN[0]/[-1]") == pytest.approx(180.0)
    assert math.isclose(value("COS[180]"), -1.0)
