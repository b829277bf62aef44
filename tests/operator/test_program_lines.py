"""The status line's program text, read from the file as shown (run/view.py, ProgramLines)."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.operator.run import view as run_view
from controller.operator.run.view import ProgramLines

LINE = st.text(alphabet=st.characters(blacklist_categories=("Cs",),
                                      blacklist_characters="\r\n"), max_size=300)


@settings(max_examples=60, deadline=None)
@given(lines=st.lists(LINE, max_size=80), newline=st.sampled_from(["\n", "\r\n", "\r"]),
       bom=st.booleans(), trailing=st.booleans(), seed=st.integers(0, 1000))
def test_every_line_as_the_file_holds_it_in_any_order(lines: list[str], newline: str, bom: bool,
                                                      trailing: bool, seed: int) -> None:
    """With a cap of 4 positions (the stride doubles several times), lines looked up forwards,
    backwards and at random are the file's lines, cut to SHOWN_CHARS; the positions kept stay
    within the cap."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp, pytest.MonkeyPatch.context() as mp:
        mp.setattr(run_view, "MAX_MARKS", 4)
        path = Path(tmp) / "p.nc"
        text = newline.join(lines) + (newline if trailing and lines else "")
        path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
        normal = text.replace("\r\n", "\n").replace("\r", "\n")  # universal newlines only
        expected = normal.split("\n") if normal else []
        if normal.endswith("\n"):
            expected = expected[:-1]
        program = ProgramLines(str(path))
        assert len(program) == len(expected)
        assert len(program.marks) <= 4
        order = list(range(len(expected)))
        random.Random(seed).shuffle(order)
        for i in [*range(len(expected)), *reversed(range(len(expected))), *order]:
            assert program[i] == expected[i][:run_view.SHOWN_CHARS]
        with pytest.raises(IndexError):
            program[len(expected)]  # noqa: B018
        program.close()


def test_a_long_program_keeps_a_bounded_index(tmp_path: Path) -> None:
    """100k lines: at most MAX_MARKS positions, and a line is found without reading the file
    from its start (at most one stride of lines)."""
    path = tmp_path / "long.nc"
    path.write_text("".join(f"G1 X{i % 100} Y{i // 100} (line {i + 1})\n"
                            for i in range(100_000)), encoding="ascii")
    program = ProgramLines(str(path))
    assert len(program) == 100_000 and len(program.marks) <= run_view.MAX_MARKS
    assert program.stride <= 2 * 100_000 // run_view.MAX_MARKS
    assert program[99_999].endswith("(line 100000)")
    assert program[12_345].endswith("(line 12346)")  # backwards: from the nearest position
    assert program[12_346].endswith("(line 12347)")
    program.close()


def test_an_unreadable_program_shows_no_text(tmp_path: Path) -> None:
    assert len(ProgramLines(str(tmp_path / "missing.nc"))) == 0
