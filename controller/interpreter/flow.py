"""O-word control flow as LinuxCNC runs it: subroutines (in the program or a file), loops, if.

The program's lines are read one at a time; from the first O-word line on they are also kept
(`LineCursor`), since every jump lands on or after an O-word line. A program without O-words is
never held in memory. Every loop is bounded: a loop that has not ended after MAX_LOOP_PASSES
passes, or a program whose loops together pass MAX_TOTAL_PASSES times, is an error naming the
loop's line, found by the check before any motion.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from controller.errors import NcError
from controller.interpreter.expr import ExprError, Reader
from controller.interpreter.owords import ASCII_UPPER, PROGRAM, OWord, peek_oword, read_oword
from controller.interpreter.params import ParamError, Parameters

MAX_LOOP_PASSES = 100_000  # one loop's passes; CAM loops (pecks, passes, holes) stay far below
MAX_TOTAL_PASSES = 1_000_000  # all loops and calls of a program together
MAX_CALL_DEPTH = 64
# The lines of a subroutine file (`o<name> call` of `name.ngc`) are numbered from
# k * EXTERNAL_LINE_BASE (k = 1, 2, ...), after any line of the program itself.
EXTERNAL_LINE_BASE = 1_000_000_000
MAX_SUB_FILE_BYTES = 1 << 20
_BRANCHES = frozenset(("ELSEIF", "ELSE", "ENDIF"))
_LOOP_END = {"WHILE": "ENDWHILE", "REPEAT": "ENDREPEAT", "DO": "WHILE"}


class LineCursor:
    """The program's raw lines by number (from 1); lines from `keep_from` on can be revisited."""

    def __init__(self, raw: Iterator[str],
                 reread: Callable[[int], list[str]] | None = None) -> None:
        self._raw = raw
        self._reread = reread  # the program's first n lines, read again from the file
        self.kept: list[str] | None = None
        self.first_kept = 0
        self.read = 0  # lines read from the file so far
        self.next_line = 1  # the number of the line the next iteration returns
        self.files: list[tuple[str, list[str]]] = []  # subroutine files: path, lines

    def __iter__(self) -> Iterator[str]:
        """The lines in the order they run (a generator: cheaper per line than __next__)."""
        raw_lines = self._raw
        while True:
            n = self.next_line
            if n >= EXTERNAL_LINE_BASE:
                raw = self.line(n)
                if raw is None:
                    return
            elif n <= self.read:
                raw = self.kept[n - self.first_kept]  # type: ignore[index]
            else:
                raw = next(raw_lines, None)
                if raw is None:
                    return
                self.read = n
                if self.kept is not None:
                    self.kept.append(raw)
            self.next_line = n + 1
            yield raw

    def keep_from(self, lineno: int, raw: str | None = None) -> None:
        """Keep line `lineno` (the one just read; read again when `raw` is None) and every
        later line."""
        if self.kept is None:
            if raw is None:  # (lines of subroutine files are kept already)
                raw = self._reread(lineno)[-1]  # type: ignore[misc]
            self.kept = [raw]
            self.first_kept = lineno

    def to_start(self) -> None:
        """Go back to line 1 (M99 in the main program): the lines before the first kept one
        are read again from the file."""
        if self.kept is None:
            self.kept, self.first_kept = self._reread(self.read), 1  # type: ignore[misc]
        elif self.first_kept > 1:
            self.kept[:0] = self._reread(self.first_kept - 1)  # type: ignore[misc]
            self.first_kept = 1
        self.next_line = 1

    def line(self, n: int) -> str | None:
        """Raw line n (n >= the first kept line); None after the end of the file."""
        if n >= EXTERNAL_LINE_BASE:
            k, i = divmod(n, EXTERNAL_LINE_BASE)
            lines = self.files[k - 1][1]
            return lines[i - 1] if 1 <= i <= len(lines) else None
        while self.read < n:
            try:
                raw = next(self._raw)
            except StopIteration:
                return None
            self.read += 1
            self.kept.append(raw)  # type: ignore[union-attr]
        return self.kept[n - self.first_kept]  # type: ignore[index]

    def jump(self, n: int) -> None:
        self.next_line = n

    def add_file(self, path: str, lines: list[str]) -> int:
        """A subroutine file's lines; returns the number its first line has here."""
        self.files.append((path, lines))
        return len(self.files) * EXTERNAL_LINE_BASE + 1

    def locate(self, path: str, n: int) -> tuple[str, int]:
        """The file and line that line number n is: the program's or a subroutine file's."""
        if n < EXTERNAL_LINE_BASE:
            return path, n
        k, i = divmod(n, EXTERNAL_LINE_BASE)
        return self.files[k - 1][0], i


@dataclass(slots=True, eq=False)
class _Loop:
    kind: str  # WHILE, DO or REPEAT
    start: int  # the line of its while, do or repeat
    passes: int = 0
    left: int = 0  # REPEAT: passes still to run


@dataclass(slots=True, eq=False)
class Frame:
    label: str | None  # the subroutine's label; None for the main program
    return_line: int
    call_line: int
    loops: dict[str, _Loop] = field(default_factory=dict)
    fanuc: bool = False  # an M98 call of a numbered program (O100 ... M99)
    start: int = 0  # M98: the line of its O100, where each repeat starts again
    left: int = 0  # M98: the repeats still to run after this one (its L word)


class Flow:
    """Runs O-word lines: moves the cursor, opens and closes subroutine scopes."""

    def __init__(self, path: str, cursor: LineCursor, params: Parameters,
                 sub_folders: tuple[str, ...] = ()) -> None:
        self.path = path
        # where `o<name> call` finds name.ngc: the program's folder, then the config's
        self.sub_folders = (os.path.dirname(os.path.abspath(path)), *sub_folders)
        self.cursor = cursor
        self.params = params
        self.subs: dict[str, int] = {}  # label -> line of its `sub`
        self.frames: list[Frame] = [Frame(None, 0, 0)]
        self.total_passes = 0
        self._closed: set[int] = set()  # lines of if/while/do/repeat whose end was found

    def run(self, ow: OWord, lineno: int, raw: str | None = None) -> None:
        self.cursor.keep_from(lineno, raw)
        getattr(self, "_" + ow.keyword.lower())(ow, lineno)

    def finish(self, lineno: int) -> None:
        """End of the program: a subroutine still running is an error."""
        if len(self.frames) > 1:
            frame = self.frames[-1]
            raise NcError(self.path, frame.call_line, 1, f"O{frame.label}",
                          f"the program ends at line {lineno} inside subroutine "
                          f"O{frame.label} (no endsub or return reached)")

    # ---- helpers ----------------------------------------------------------------------------
    def _error(self, ow: OWord, lineno: int, message: str) -> NcError:
        return NcError(self.path, lineno, ow.col, ow.name, message)

    def _value(self, ow: OWord, lineno: int, what: str) -> float:
        reader = Reader(ow.text, self.params)
        pos = reader.skip(ow.arg_pos)
        if pos >= len(ow.text) or ow.text[pos] in "(;":
            raise self._error(ow, lineno, f"{ow.name} needs {what} in [ ]")
        try:
            return reader.value(pos)[0]
        except ExprError as exc:
            raise NcError(self.path, lineno, exc.pos + 1, ow.name, exc.message) from None

    def _args(self, ow: OWord, lineno: int) -> list[float]:
        reader = Reader(ow.text, self.params)
        args: list[float] = []
        pos = reader.skip(ow.arg_pos)
        try:
            while pos < len(ow.text) and ow.text[pos] not in "(;":
                value, pos = reader.value(pos)
                args.append(value)
                pos = reader.skip(pos)
        except ExprError as exc:
            raise NcError(self.path, lineno, exc.pos + 1, ow.name, exc.message) from None
        return args

    def _find(self, ow: OWord, lineno: int, keywords: frozenset[str] | set[str]
              ) -> tuple[int, str]:
        """The next line after `lineno` with this label and one of `keywords`."""
        n = lineno + 1
        while (raw := self.cursor.line(n)) is not None:
            head = peek_oword(raw)
            if head is not None and head[0] == ow.label and head[1] in keywords:
                return n, head[1]
            n += 1
        wanted = " or ".join(f"O{ow.label} {k.lower()}" for k in sorted(keywords))
        raise self._error(ow, lineno, f"{ow.name} without {wanted} after it")

    def _closes(self, ow: OWord, lineno: int, keyword: str) -> None:
        """An if, while, do or repeat must have its end in the file, even when it is never
        reached (LinuxCNC refuses such a program too); found once per line."""
        if lineno not in self._closed:
            self._find(ow, lineno, {keyword})
            self._closed.add(lineno)

    def _pass(self, ow: OWord, lineno: int, loop: _Loop) -> None:
        loop.passes += 1
        self.total_passes += 1
        if loop.passes > MAX_LOOP_PASSES:
            raise self._error(ow, loop.start, f"the loop O{ow.label} did not end within "
                                              f"{MAX_LOOP_PASSES} passes")
        if self.total_passes > MAX_TOTAL_PASSES:
            raise self._error(ow, loop.start, f"the program's loops passed more than "
                                              f"{MAX_TOTAL_PASSES} times in all")

    def _loop(self, ow: OWord, lineno: int) -> _Loop:
        loop = self.frames[-1].loops.get(ow.label)
        if loop is None:
            raise self._error(ow, lineno, f"{ow.name} outside a loop O{ow.label}")
        return loop

    # ---- subroutines ------------------------------------------------------------------------
    def _sub(self, ow: OWord, lineno: int) -> None:
        if self.frames[-1].fanuc:
            raise self._error(ow, lineno, f"{ow.name} inside the numbered program "
                                          f"O{self.frames[-1].label} (an M98 call runs up to M99)")
        self.subs[ow.label] = lineno
        end, _ = self._find(ow, lineno, {"ENDSUB"})
        self.cursor.jump(end + 1)  # the body runs only when called

    def _call(self, ow: OWord, lineno: int) -> None:
        args = self._args(ow, lineno)
        start = self.subs.get(ow.label)
        if start is None:  # defined later in the file: LinuxCNC looks ahead for it too
            try:
                start, keyword = self._find(ow, lineno, {"SUB", PROGRAM})
            except NcError:
                start, keyword = self._sub_file(ow, lineno), "SUB"
            if keyword == PROGRAM:
                raise self._error(ow, start, f"O{ow.label} is a numbered program (O{ow.label} "
                                             f"... M99): call it with M98 P{ow.label}")
            self.subs[ow.label] = start
        if len(self.frames) > MAX_CALL_DEPTH:
            raise self._error(ow, lineno, f"subroutine calls nested deeper than "
                                          f"{MAX_CALL_DEPTH} (endless recursion?)")
        self.total_passes += 1
        if self.total_passes > MAX_TOTAL_PASSES:
            raise self._error(ow, lineno, f"the program's loops and calls passed more than "
                                          f"{MAX_TOTAL_PASSES} times in all")
        try:
            self.params.call(args)
        except ParamError as exc:
            raise self._error(ow, lineno, str(exc)) from None
        self.frames.append(Frame(ow.label, lineno + 1, lineno))
        self.cursor.jump(start + 1)

    def _sub_file(self, ow: OWord, lineno: int) -> int:
        """`o<name> call` of a subroutine not in the program: the `o<name> sub` of `name.ngc`
        in the program's folder or a folder of the config's gcode.subroutine_path (LinuxCNC
        looks in its SUBROUTINE_PATH folders the same way)."""
        missing = f"no subroutine O{ow.label} sub in the program"
        if not ow.label.startswith("<"):
            raise self._error(ow, lineno, missing)
        if "/" in ow.label or "\\" in ow.label or ow.label.startswith("<."):
            raise self._error(ow, lineno, f"{missing}; a file name without folders is looked "
                                          "up (a name with '/', '\\' or a leading '.' is not)")
        name = ow.label[1:-1] + ".ngc"
        found = [p for p in (os.path.join(d, name) for d in self.sub_folders) if os.path.isfile(p)]
        if not found:
            raise self._error(ow, lineno, f"{missing} nor a file {name} in "
                                          f"{', '.join(self.sub_folders)}")
        sub_path = found[0]
        try:
            with open(sub_path, "rb") as f:
                data = f.read(MAX_SUB_FILE_BYTES + 1)
        except OSError as exc:
            raise self._error(ow, lineno, f"cannot read {sub_path}: {exc.strerror}") from None
        if len(data) > MAX_SUB_FILE_BYTES:
            raise self._error(ow, lineno, f"subroutine file {sub_path} is larger than "
                                          f"{MAX_SUB_FILE_BYTES >> 20} MiB")
        lines = data.decode("utf-8-sig", errors="replace").splitlines()
        first = self.cursor.add_file(sub_path, lines)
        for n in range(first, first + len(lines)):
            head = peek_oword(lines[n - first])
            if head is not None and head[0] == ow.label and head[1] == "SUB":
                return n
        raise self._error(ow, lineno, f"{sub_path} has no O{ow.label} sub")

    def _endsub(self, ow: OWord, lineno: int) -> None:
        frame = self.frames[-1]
        if frame.label is None:
            raise self._error(ow, lineno, f"{ow.name} outside a subroutine call")
        if frame.fanuc:
            raise self._error(ow, lineno, f"{ow.name} inside the numbered program "
                                          f"O{frame.label}, which ends with M99")
        if frame.label != ow.label and ow.keyword == "ENDSUB":
            # a return may carry another label (LinuxCNC's retval.ngc: `o1010 return` inside
            # `o1010 if`, in o1000); an endsub closes its own subroutine only
            raise self._error(ow, lineno, f"{ow.name} inside subroutine O{frame.label}")
        rest = ow.text[ow.arg_pos:].strip()
        if rest and not rest.startswith(("(", ";")):
            self.params.set_named("_value", self._value(ow, lineno, "a value"))
            self.params.set_named("_value_returned", 1.0)
        self.frames.pop()
        self.params.ret()
        self.cursor.jump(frame.return_line)

    _return = _endsub

    def _program(self, ow: OWord, lineno: int) -> None:
        """A bare O100 reached in the flow: the lines go on into its body (LinuxCNC 2.9: a
        main program's number, or a numbered program the flow runs into)."""
        frame = self.frames[-1]
        if frame.label is not None and not frame.fanuc:
            raise self._error(ow, lineno, f"{ow.name} inside subroutine O{frame.label}: a "
                                          f"numbered program is called with M98 P{ow.label}")

    # ---- if ---------------------------------------------------------------------------------
    def _if(self, ow: OWord, lineno: int) -> None:
        self._closes(ow, lineno, "ENDIF")
        n = lineno
        cond = self._value(ow, lineno, "a condition")
        while cond == 0.0:
            n, keyword = self._find(ow, n, _BRANCHES)
            if keyword != "ELSEIF":
                break
            raw = self.cursor.line(n) or ""
            branch = read_oword(raw.translate(ASCII_UPPER), self.path, n)
            cond = self._value(branch, n, "a condition")
        self.cursor.jump(n + 1)

    def _elseif(self, ow: OWord, lineno: int) -> None:
        end, _ = self._find(ow, lineno, {"ENDIF"})  # the branch before ran: skip the others
        self.cursor.jump(end + 1)

    _else = _elseif

    def _endif(self, ow: OWord, lineno: int) -> None:
        pass

    # ---- loops ------------------------------------------------------------------------------
    def _while(self, ow: OWord, lineno: int) -> None:
        loops = self.frames[-1].loops
        loop = loops.get(ow.label)
        cond = self._value(ow, lineno, "a condition")
        if loop is None or loop.kind != "DO":
            self._closes(ow, lineno, "ENDWHILE")
        if loop is not None and loop.kind == "DO" and loop.start < lineno:  # do ... while
            if cond != 0.0:
                self._pass(ow, lineno, loop)
                self.cursor.jump(loop.start + 1)
            else:
                del loops[ow.label]
            return
        if cond == 0.0:
            loops.pop(ow.label, None)
            end, _ = self._find(ow, lineno, {"ENDWHILE"})
            self.cursor.jump(end + 1)
            return
        if loop is None or loop.start != lineno:
            loop = loops[ow.label] = _Loop("WHILE", lineno)
        self._pass(ow, lineno, loop)

    def _endwhile(self, ow: OWord, lineno: int) -> None:
        self.cursor.jump(self._loop(ow, lineno).start)  # the while line tests again

    def _do(self, ow: OWord, lineno: int) -> None:
        self._closes(ow, lineno, "WHILE")
        self.frames[-1].loops[ow.label] = _Loop("DO", lineno)

    def _repeat(self, ow: OWord, lineno: int) -> None:
        self._closes(ow, lineno, "ENDREPEAT")
        count = round(self._value(ow, lineno, "a count"))
        if count <= 0:
            end, _ = self._find(ow, lineno, {"ENDREPEAT"})
            self.cursor.jump(end + 1)
            return
        loop = self.frames[-1].loops[ow.label] = _Loop("REPEAT", lineno, left=count)
        self._pass(ow, lineno, loop)

    def _endrepeat(self, ow: OWord, lineno: int) -> None:
        loop = self._loop(ow, lineno)
        loop.left -= 1
        if loop.left > 0:
            self._pass(ow, lineno, loop)
            self.cursor.jump(loop.start + 1)
        else:
            del self.frames[-1].loops[ow.label]

    def _break(self, ow: OWord, lineno: int) -> None:
        loop = self._loop(ow, lineno)
        del self.frames[-1].loops[ow.label]
        end, _ = self._find(ow, lineno, {_LOOP_END[loop.kind]})
        self.cursor.jump(end + 1)

    def _continue(self, ow: OWord, lineno: int) -> None:
        loop = self._loop(ow, lineno)
        if loop.kind == "WHILE":
            self.cursor.jump(loop.start)
        else:  # do: its closing while tests; repeat: its endrepeat counts
            end, _ = self._find(ow, lineno, {_LOOP_END[loop.kind]})
            self.cursor.jump(end)
