"""O-words as LinuxCNC runs them: sub, call, return, if, elseif, else, while, do, repeat, break."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import XY_TABLE, blocks_of

from controller.errors import NcError
from controller.interpreter.flow import MAX_LOOP_PASSES, LineCursor
from controller.interpreter.program import Interpreter


def xs(tmp_path: Path, text: str) -> list[float]:
    return [b.end[0] for b in blocks_of(tmp_path, text) if hasattr(b, "end") and b.end]


def test_subroutine_with_arguments_and_local_scope(tmp_path: Path) -> None:
    text = """#1 = 100
#<x> = 7
o<square> sub
  #<x> = [#1 * #1]
  G0 X#<x> Y#2
o<square> endsub
o<square> call [2] [5]
o<square> call [3]
G0 X#1 Y#<x>
M2
"""
    b = blocks_of(tmp_path, text)
    # #2 is 0 in the second call (an argument not passed); #1 and #<x> come back after it
    assert [blk.end[:2] for blk in b[:-1]] == [(4.0, 5.0), (9.0, 0.0), (100.0, 7.0)]


def test_return_value_and_call_before_definition(tmp_path: Path) -> None:
    text = """o200 call [3]
G0 X#<_value>
M2
o200 sub
  o200 return [#1 * 10]
  G0 X999
o200 endsub
"""
    assert xs(tmp_path, text)[0] == 30.0


def test_if_elseif_else(tmp_path: Path) -> None:
    text = """o1 repeat [4]
  #<n> = [#<_i> + 0]
  o2 if [#<n> EQ 0]
    G0 X10
  o2 elseif [#<n> EQ 1]
    G0 X11
  o2 elseif [#<n> LT 3]
    G0 X12
  o2 else
    G0 X13
  o2 endif
  #<_i> = [#<_i> + 1]
o1 endrepeat
"""
    assert xs(tmp_path, "#<_i> = 0\n" + text) == [10.0, 11.0, 12.0, 13.0]


def test_while_do_break_continue(tmp_path: Path) -> None:
    text = """#1 = 0
o10 while [#1 LT 10]
  #1 = [#1 + 1]
  o11 if [#1 MOD 2 EQ 0]
    o10 continue
  o11 endif
  o12 if [#1 GT 7]
    o10 break
  o12 endif
  G0 X#1
o10 endwhile
#2 = 0
o20 do
  #2 = [#2 + 1]
  G0 Y#2
o20 while [#2 LT 3]
M2
"""
    b = blocks_of(tmp_path, text)
    assert [blk.end[0] for blk in b[:4]] == [1.0, 3.0, 5.0, 7.0]
    assert [blk.end[1] for blk in b[4:7]] == [1.0, 2.0, 3.0]


def test_repeat_zero_skips_and_nested_loops(tmp_path: Path) -> None:
    text = """#<_n> = 0
o1 repeat [0]
  G0 X99
o1 endrepeat
o2 repeat [3]
  o3 repeat [2]
    #<_n> = [#<_n> + 1]
    G0 X#<_n>
  o3 endrepeat
o2 endrepeat
"""
    assert xs(tmp_path, text) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


@settings(max_examples=30, deadline=None)
@given(counts=st.lists(st.integers(0, 6), min_size=1, max_size=3))
def test_nested_repeat_counts(tmp_path_factory: pytest.TempPathFactory,
                              counts: list[int]) -> None:
    """Nested repeats run the product of their counts, in order, whatever the counts."""
    tmp = tmp_path_factory.mktemp("rep")
    head = "".join(f"o{i} repeat [{c}]\n" for i, c in enumerate(counts))
    tail = "".join(f"o{i} endrepeat\n" for i in reversed(range(len(counts))))
    text = "#<_n> = 0\n" + head + "#<_n> = [#<_n> + 1]\nG0 X#<_n>\n" + tail
    expected = 1
    for c in counts:
        expected *= c
    assert xs(tmp, text) == [float(i) for i in range(1, expected + 1)]


def test_endless_loop_is_an_error_naming_its_line(tmp_path: Path) -> None:
    t0 = time.process_time()
    with pytest.raises(NcError) as info:
        blocks_of(tmp_path, "G0 X1\n#1 = 0\no100 while [1]\n  #1 = [#1 + 1]\no100 endwhile\n")
    assert info.value.line == 3 and "O100" in info.value.word
    assert f"did not end within {MAX_LOOP_PASSES} passes" in info.value.message
    assert time.process_time() - t0 < 60  # bounded: a few seconds of CPU


def test_structure_errors(tmp_path: Path) -> None:
    cases = [
        ("o1 if [1]\nG0 X1\n", 1, "without O1 endif"),
        ("o1 endwhile\n", 1, "outside a loop"),
        ("o1 endsub\n", 1, "outside a subroutine call"),
        ("o5 call\n", 1, "no subroutine O5"),
        ("o1 sub\nG0 X1\n", 1, "without O1 endsub"),
        ("o1 while\no1 endwhile\n", 1, "needs a condition"),
        ("o1 frob\n", 1, "unknown O-word keyword"),
        ("G0 X1\no1 sub\no1 call\no1 endsub\no1 call\n", 3, "nested deeper"),
        ("o1 sub\nM2\n", 1, "without O1 endsub"),
    ]
    for text, line, fragment in cases:
        with pytest.raises(NcError) as info:
            blocks_of(tmp_path, text)
        assert info.value.line == line and fragment in info.value.message, text


def test_whole_program_is_checked_before_blocks(tmp_path: Path) -> None:
    """An error inside a loop is found by reading the program: the check sees it, so no motion
    starts (the daemon and cncctl run check the whole program first)."""
    text = "o1 repeat [3]\nG0 X#<_k>\n#<_k> = 1\no1 endrepeat\n"
    with pytest.raises(NcError, match="#<_k> is not set"):
        blocks_of(tmp_path, text)


def test_program_without_owords_is_not_kept(tmp_path: Path) -> None:
    path = tmp_path / "plain.nc"
    path.write_text("".join(f"G1 X{i % 50 + 1} F100\n" for i in range(2000)))
    interp = Interpreter(str(path), XY_TABLE)
    seen: list[LineCursor] = []
    original = LineCursor.__init__

    def spy(self: LineCursor, *args) -> None:  # noqa: ANN002
        original(self, *args)
        seen.append(self)

    LineCursor.__init__ = spy  # type: ignore[method-assign]
    try:
        with path.open() as handle:
            assert sum(1 for _ in interp.run(handle)) == 2000
    finally:
        LineCursor.__init__ = original  # type: ignore[method-assign]
    assert seen and seen[0].kept is None
