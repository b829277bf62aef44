"""Lexer: words, comments, case, block delete, %, parameters, columns and lexical errors."""

from __future__ import annotations

import pytest

from controller.errors import NcError
from controller.interpreter.lexer import MAX_LINE_CHARS, Line, lex_line
from controller.interpreter.params import Parameters


def lex(text: str) -> Line:
    line = lex_line(text, "p.nc", 1)
    assert isinstance(line, Line)
    return line


def test_plain_words_and_case() -> None:
    line = lex("n10 g1 x-1.5 Y+.25 f1000.")
    assert line.words == [("N", "10"), ("G", "1"), ("X", "-1.5"), ("Y", "+.25"), ("F", "1000.")]


def test_spaces_between_letter_and_number() -> None:
    assert lex("G 1 X 2").words == [("G", "1"), ("X", "2")]


def test_columns_are_one_based_and_exact() -> None:
    line = lex("G1  X10 (note) Y20 ; tail")
    assert [line.col(i) for i in range(3)] == [1, 5, 16]
    fast = lex("G1  X10   Y20")
    assert [fast.col(i) for i in range(3)] == [1, 5, 11]


def test_comments_are_removed() -> None:
    assert lex("(only a comment)").words == []
    assert lex("G0 X1 ; Y2 (not read)").words == [("G", "0"), ("X", "1")]
    assert lex("G0 (a;b) X1").words == [("G", "0"), ("X", "1")]


def test_block_delete_and_percent() -> None:
    assert lex_line("/G0 X100", "p.nc", 1) is None
    assert lex_line("  / G0 X100", "p.nc", 1) is None
    assert lex_line(" % ", "p.nc", 1) == "%"


def test_parameter_reference_and_assignment() -> None:
    line = lex("#10 = 290 ; feed")
    assert line.assigns == [(10, 290.0, 1)] and line.words == []
    params = Parameters()
    params.set(10, 290.0)
    ref = lex_line("F#10", "p.nc", 1, params)
    assert ref.words == [("F", "290.0")]
    named = lex_line("#<Depth> = [#10 / 2]", "p.nc", 1, params)
    assert named.assigns == [("depth", 145.0, 1)]


@pytest.mark.parametrize(("text", "col", "fragment"), [
    ("G0 X1 & Y2", 7, "unexpected character '&'"),
    ("G0 X", 4, "X word without a number"),
    ("G0 X1 (open", 7, "comment not closed"),
    ("G0 (a (b) c)", 7, "nested comment"),
    ("G0 X[1", 4, "expression not closed"),
    ("G0 X" + "9" * 25, 4, "number too long"),
    ("G0 X1 / Y1", 7, "unexpected character '/'"),
    ("G0 O100", 4, "an O-word must stand first"),
    ("#1 2", 1, "needs '='"),
    ("G0\x00", 3, "U+0000"),
])
def test_lexical_errors_name_the_column(text: str, col: int, fragment: str) -> None:
    with pytest.raises(NcError) as info:
        lex_line(text, "p.nc", 7)
    assert info.value.line == 7 and info.value.col == col
    assert fragment in info.value.message


def test_too_long_line() -> None:
    with pytest.raises(NcError, match="line longer than"):
        lex_line("G1 X1 " + " " * MAX_LINE_CHARS, "p.nc", 1)
