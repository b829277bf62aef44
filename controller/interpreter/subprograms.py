"""M98/M99: Fanuc-style numbered programs (O100 ... M99 in the same file) as LinuxCNC 2.9 runs them.

`M98 P100 L3` runs the lines after `O100` up to `M99` three times (L0: not at all); the
program O100 must follow the call in the file (LinuxCNC looks for it only forward, and
remembers it once found). #1-#30 stay shared with the caller (an `o100 call` saves them); named
parameters set in the program are its own. `M99` in the main program goes back to the first
line and runs the program again with the state it has (LinuxCNC's endless program, as its task
runs it; its standalone rs274 ends the program there instead): the program must end within
MAX_PROGRAM_PASSES passes, else an error names the M99 line. With `gcode.main_program_m99: end`
it ends the job there instead, as M2 (Centroid's rule: centroid.py). The two styles do not mix: an
`O100 sub` is called with `O100 call` and ends with `O100 endsub`, an `O100` with `M98` and `M99`.
"""

from __future__ import annotations

from collections.abc import Callable

from controller.interpreter.codes import WordError
from controller.interpreter.flow import (
    EXTERNAL_LINE_BASE,
    MAX_CALL_DEPTH,
    MAX_TOTAL_PASSES,
    Flow,
    Frame,
)
from controller.interpreter.owords import ASCII_UPPER, KEYWORDS, PROGRAM, peek_oword, read_oword

# Whole-program passes of a main program that M99 sends back to its start. A program meant to
# repeat (a counter and an `O.. if` ending it with M2) stays far below; an endless one (the
# usual M99 warm-up loop) would otherwise be read for minutes before its total passes ran out.
MAX_PROGRAM_PASSES = 1000
_NOT_A_START = KEYWORDS - {"SUB"}  # an O100 line of these keywords does not start O100
_LOOP_COUNT_TOLERANCE = 1e-4  # LinuxCNC's tolerance for a whole number (its "integer" words)


class Subprograms:
    """The M98 calls and M99 returns of a program, on the flow of its O-word lines."""

    def __init__(self, flow: Flow, warn_word: Callable[[int, str, str], None],
                 end_main: Callable[[int], None] | None = None) -> None:
        self.flow = flow
        self.warn_word = warn_word
        self.end_main = end_main  # M99 in the main program ends the job (Centroid), not restarts
        self.program_passes = 0

    def m98(self, vals: dict[str, float], lineno: int) -> None:
        """M98 P<number> [L<count>] (the line's other words were checked by the caller)."""
        if "P" not in vals:
            raise WordError(
                "M98",
                "M98 needs P: the number of the program to call (M98 P100 "
                "runs the lines after O100 up to M99)",
            )
        label = _whole(vals["P"], "P", "M98 P: a program number is a whole number >= 0")
        count = 1
        if "L" in vals:
            count = _whole(vals["L"], "L", "M98 L: the repeat count is a whole number >= 0")
        if count == 0:
            return  # LinuxCNC does not look for the program either
        self.flow.cursor.keep_from(lineno)  # the return lands on the next line
        start = self._program_line(str(label), lineno)
        flow = self.flow
        if len(flow.frames) > MAX_CALL_DEPTH:
            raise WordError(
                "M98", f"M98 calls nested deeper than {MAX_CALL_DEPTH} (endless recursion?)"
            )
        self._count_pass("M98")
        flow.params.call(None)
        flow.frames.append(
            Frame(str(label), lineno + 1, lineno, fanuc=True, start=start, left=count - 1)
        )
        flow.cursor.jump(start + 1)

    def m99(self, lineno: int) -> None:
        """M99: the end of a numbered program (again for the repeats left), or in the main
        program the way back to its first line."""
        flow = self.flow
        frame = flow.frames[-1]
        if frame.label is None:
            if self.end_main is not None:
                self.end_main(lineno)
            else:
                self._to_start(lineno)
            return
        if not frame.fanuc:
            raise WordError(
                "M99",
                f"M99 inside subroutine O{frame.label}, which ends with "
                f"O{frame.label} endsub or return (M99 ends an O{frame.label} "
                "called by M98)",
            )
        flow.params.ret()
        if frame.left > 0:
            frame.left -= 1
            self._count_pass("M99")
            flow.params.call(None)
            frame.loops.clear()
            flow.cursor.jump(frame.start + 1)
            return
        flow.frames.pop()
        flow.cursor.jump(frame.return_line)

    def _program_line(self, label: str, lineno: int) -> int:
        """The line of `O<label>`: known from an earlier call, else the next one after the call."""
        flow = self.flow
        start = flow.subs.get(label)
        if start is None:
            start = self._find_forward(label, lineno)
            flow.subs[label] = start
        text = (flow.cursor.line(start) or "").translate(ASCII_UPPER)
        if read_oword(text, flow.path, start).keyword != PROGRAM:  # an error if malformed
            raise WordError(
                "P",
                f"M98 P{label}: O{label} is a subroutine (O{label} sub ... "
                f"endsub), called with O{label} call",
            )
        return start

    def _find_forward(self, label: str, lineno: int) -> int:
        cursor = self.flow.cursor
        n = lineno + 1
        while (raw := cursor.line(n)) is not None:
            head = peek_oword(raw)
            if head is not None and head[0] == label and head[1] not in _NOT_A_START:
                return n
            n += 1
        line = cursor.locate(self.flow.path, lineno)[1]
        before = self._find_before(label, lineno)
        where = f" (it stands before, at line {before})" if before else ""
        raise WordError(
            "P",
            f"M98 P{label}: no program O{label} after line {line}{where}; "
            f"LinuxCNC looks for a numbered program O{label} ... M99 only "
            "after its call in the file",
        )

    def _find_before(self, label: str, lineno: int) -> int | None:
        """A line O<label> among the kept lines before the call (for the error message)."""
        cursor = self.flow.cursor
        first = cursor.first_kept if lineno < EXTERNAL_LINE_BASE else lineno
        for n in range(first, lineno):
            head = peek_oword(cursor.line(n) or "")
            if head is not None and head[0] == label and head[1] == PROGRAM:
                return n
        return None

    def _to_start(self, lineno: int) -> None:
        flow = self.flow
        if self.program_passes == 0:
            self.warn_word(
                lineno,
                "M99",
                "M99 in the main program starts it again from its "
                "first line (LinuxCNC's task; its rs274 ends the "
                "program there)",
            )
        self.program_passes += 1
        if self.program_passes > MAX_PROGRAM_PASSES:
            raise WordError(
                "M99",
                f"M99 in the main program starts it again (LinuxCNC's "
                f"endless program): the program did not end within "
                f"{MAX_PROGRAM_PASSES} passes",
            )
        self._count_pass("M99")
        flow.frames[0].loops.clear()
        flow.cursor.to_start()

    def _count_pass(self, word: str) -> None:
        flow = self.flow
        flow.total_passes += 1
        if flow.total_passes > MAX_TOTAL_PASSES:
            raise WordError(
                word,
                f"the program's loops and calls passed more than {MAX_TOTAL_PASSES} times in all",
            )


def _whole(value: float, letter: str, message: str) -> int:
    whole = round(value)
    if value < 0 or abs(value - whole) > _LOOP_COUNT_TOLERANCE:
        raise WordError(letter, f"{message}, not {value:g}")
    return whole
