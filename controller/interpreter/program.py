"""NC interpreter: streams an RS274/NGC file into typed NC blocks (machine mm, mm/s).

Public API: `read_program(path, config, start_mm, offsets, from_line, track)`, and
`position_at_line` / `final_offsets`. Memory stays bounded: one line is read at a time and only
the current NURBS block (at most MAX_CONTROL_POINTS points) is held.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from itertools import islice
from typing import TextIO

from controller.blocks import NcBlock, NurbsBlock, Source
from controller.config import MachineConfig, load_config
from controller.errors import NcError
from controller.geometry.nurbs import Nurbs
from controller.interpreter.centroid import M25_CODE, CentroidCodes
from controller.interpreter.codes import (
    G_GROUP,
    G_UNSUPPORTED,
    M_GROUP,
    WordError,
    g_code10,
    g_name,
    m_refusal,
)
from controller.interpreter.flow import EXTERNAL_LINE_BASE, Flow, LineCursor
from controller.interpreter.lexer import CLEAN_RE, MAX_LINE_CHARS, WORD_RE, Line, lex_line
from controller.interpreter.line_state import LineState
from controller.interpreter.mach3 import G31_CODE10, Mach3Probing
from controller.interpreter.owords import NO_KEYWORD, OWord, read_oword
from controller.interpreter.params import ParamError
from controller.interpreter.state import InterpState
from controller.interpreter.subprograms import Subprograms
from controller.offsets import OffsetTable, ProgramOffsets

_G_CACHE: dict[str, int] = {}  # G number text -> code10, for supported/known codes only
_G_BY_VALUE: dict[float, int] = {}  # the same by value (G01 and G1 alike)
_M_CACHE: dict[str, int] = {}
_VALUE_LETTERS = frozenset("XYZIJKRPQLFSTHE@^")  # @ ^: polar radius and angle
_CHUNK_CHARS = 1 << 16


def read_program(path: str, config: MachineConfig,
                 start_mm: tuple[float, float, float] | None = None,
                 offsets: OffsetTable | None = None, from_line: int | None = None,
                 track: ProgramOffsets | None = None) -> Iterator[NcBlock]:
    """Yield the NC blocks of a program one by one, in machine coordinates; raise NcError at
    the first mistake. The machine starts at start_mm (machine coordinates, default X0 Y0 Z0:
    where a freshly opened drive stands) with the work offsets `offsets` (default: all zero,
    G54). `track`, if given, always holds the offset table in force after the last line read.

    from_line N: the lines before N are read and checked (modes, feed, offsets, position) but
    yield nothing; the blocks from the first line at or after N on are yielded as in the whole
    program, so the first motion block starts where the program stands at line N. N inside a
    multi-line NURBS block, or after the program's end, is an NcError naming line N."""
    yield from _open_and_run(Interpreter(path, config, start_mm, offsets, track), from_line)


def position_at_line(path: str, config: MachineConfig, line: int,
                     start_mm: tuple[float, float, float] | None = None,
                     offsets: OffsetTable | None = None) -> LineState:
    """Machine position and modal state (feed, G90/G91, G20/G21, work offsets, G61/G64,
    spindle, coolant, tool) just before `line` runs; the program is read up to there."""
    interp = Interpreter(path, config, start_mm, offsets)
    blocks = _open_and_run(interp, line)
    for _ in blocks:
        break
    blocks.close()
    if interp.state.at_line is None:  # run() raises first when line N is never reached
        raise NcError(path, line, 0, "", f"cannot run from line {line}")
    return interp.state.at_line


def final_offsets(path: str, config: MachineConfig,
                  start_mm: tuple[float, float, float] | None = None,
                  offsets: OffsetTable | None = None) -> OffsetTable:
    """The offset table a whole program leaves behind (G10, G92, G54-G59), without motion.
    (A caller that checks the program anyway gets it in the same pass: read_program's track.)"""
    track = ProgramOffsets()
    for _ in read_program(path, config, start_mm, offsets, track=track):
        pass
    return track.table


def _open_and_run(interp: Interpreter, from_line: int | None) -> Iterator[NcBlock]:
    path = interp.path
    try:
        handle = open(path, encoding="utf-8-sig", errors="replace", newline=None)  # noqa: SIM115
    except OSError as exc:
        raise NcError(path, 0, 0, "", f"cannot open program: {exc.strerror or exc}") from exc
    with handle:
        try:
            yield from interp.run(handle, from_line)
        except NcError as exc:
            if exc.line < EXTERNAL_LINE_BASE or interp.cursor is None:
                raise
            sub_path, line = interp.cursor.locate(path, exc.line)  # in a subroutine file
            raise NcError(sub_path, line, exc.col, exc.word, exc.message) from None


class Interpreter:
    """Reads lines, checks words and modal groups, and hands each line to InterpState."""

    def __init__(self, path: str, config: MachineConfig,
                 start_mm: tuple[float, float, float] | None = None,
                 offsets: OffsetTable | None = None,
                 track: ProgramOffsets | None = None) -> None:
        self.path = path
        self.state = InterpState(path, config, start_mm, offsets, track)
        self.params = self.state.params
        self.percent_seen = False
        self.cursor: LineCursor | None = None  # the lines, once run() opens them
        self.ended_by_percent = False
        self.words_seen = False
        self.mach3 = Mach3Probing(path, self.state.warn_word)
        self.centroid = CentroidCodes(self.state)  # M25, M99 ending the main program

    def run(self, handle: TextIO, from_line: int | None = None) -> Iterator[NcBlock]:
        """The blocks of the program; from `from_line` on only (see read_program)."""
        out = self.state.out
        lineno = 0
        first = 1 if from_line is None else from_line
        if first < 1:
            raise NcError(self.path, first, 0, "",
                          f"cannot run from line {first}: lines are numbered from 1")
        emitting = from_line is None and not self.state.probing.results.resume_after
        cursor = self.cursor = LineCursor(_raw_lines(handle, self.path),
                                          lambda n: _first_lines(self.path, n))
        self.state.locate = lambda n: cursor.locate(self.path, n)
        flow = self.flow = Flow(self.path, cursor, self.params,
                                self.state.config.gcode.subroutine_path)
        end_job = self.centroid.end_job if self.centroid.ends_job else None
        self.subprograms = Subprograms(flow, self.state.warn_word, end_job)
        for raw in cursor:
            lineno = cursor.next_line - 1
            if not emitting and from_line and first <= lineno < EXTERNAL_LINE_BASE:
                emitting = self._start_here(first)
            text = raw.upper()
            # The hot path (almost every line of a CAM program): plain ASCII words, no comment.
            if raw.isascii() and len(text) <= MAX_LINE_CHARS and CLEAN_RE.fullmatch(text):
                words = WORD_RE.findall(text)
                if words:
                    self._execute_plain(words, text, lineno)
            else:
                line = lex_line(raw, self.path, lineno, self.params)
                if self.params.unset_reads:
                    self._warn_unset(lineno)
                if line is None:
                    continue
                if line == "%":
                    if self._percent(lineno):
                        break
                    continue
                if isinstance(line, OWord):
                    self._oword(line, lineno, raw)
                    continue
                self._execute(line, lineno)  # type: ignore[arg-type]
            emitting = emitting or self.state.at_line is not None
            if out:
                if emitting:
                    yield from (out if lineno < EXTERNAL_LINE_BASE else self._located(out))
                out.clear()
            if self.state.ended or self.state.probing.stop_reading:
                break  # M2/M30, or a probe whose result decides the rest (a run)
        if not self.state.ended and not self.state.probing.stop_reading:
            flow.finish(lineno)
            if not self.ended_by_percent and self.words_seen:
                self.state.warn(lineno, "the program ends without M2, M30 or a closing %: read "
                                        "to the end of the file (LinuxCNC refuses it)")
        self.state.finish_program(lineno)
        if not emitting and self.state.mark_pending is not None:
            self.state.mark(first)  # a G6.2 block ended by the end of the file, before `first`
            emitting = True
        if not emitting:
            raise NcError(self.path, first, 0, "", f"cannot run from line {first}: the "
                                                   f"program ends at line {lineno}")
        yield from out
        out.clear()

    def _oword(self, ow: OWord, lineno: int, raw: str | None = None) -> None:
        self.words_seen = True
        self.state.contexts.return_line = lineno  # an M73 return's blocks
        self.flow.run(ow, lineno, raw)
        if self.params.unset_reads:
            self._warn_unset(lineno)

    def _located(self, blocks: list[NcBlock]) -> list[NcBlock]:
        """Blocks of a subroutine file's lines, with that file and its line numbers."""
        located = []
        for block in blocks:
            src = block.source
            path, first = self.cursor.locate(self.path, src.first_line)  # type: ignore[union-attr]
            last = first + src.last_line - src.first_line
            located.append(replace(block, source=Source(path, first, last)))  # type: ignore[type-var]
        return located

    def _warn_unset(self, lineno: int) -> None:
        """Numbered parameters the line read before any setting: 0, as LinuxCNC reads them."""
        for number in dict.fromkeys(self.params.unset_reads):
            self.state.warn_word(lineno, f"#{number}", f"parameter #{number} is not set: read "
                                 "as 0 (LinuxCNC's rule for a numbered parameter)")
        self.params.unset_reads.clear()

    def _start_here(self, line: int) -> bool:
        """Run from `line`: the state here starts the run, unless a NURBS block is open (G5.2:
        an error; G6.2: the state decides at the next line that does not belong to it)."""
        state = self.state
        if state.moves.nurbs is None:
            state.mark(line)
            return True
        if state.moves.nurbs.kind == "G5.2":
            raise state.inside_nurbs(line)
        state.mark_pending = line
        return False

    def _execute_plain(self, words: list[tuple[str, str]], text: str, lineno: int) -> None:
        """A line of plain words; the usual case (each letter once, one G, no M) inline."""
        self.words_seen = True
        vals = {k: float(v) for k, v in words}
        if len(vals) == len(words) and "M" not in vals:
            g = vals.pop("G", None)
            vals.pop("N", None)
            code = -1 if g is None else _G_BY_VALUE.get(g)
            if code is not None and _VALUE_LETTERS.issuperset(vals):
                state = self.state
                try:
                    moves = state.moves  # with a NURBS block open: its point lines
                    if not (state.fast(code, vals, lineno) if moves.nurbs is None else
                            state.mark_pending is None and moves.g6_line(code, vals, lineno)):
                        state.execute([] if code < 0 else [code], [], vals, lineno)
                except WordError as exc:
                    raise self._error(Line(words, text), lineno, exc.word, exc.message) from None
                return
        self._execute(Line(words, text), lineno)

    def _percent(self, lineno: int) -> bool:
        """`%` before any code opens the program; any later `%` ends it (LinuxCNC: only a
        program opened by `%` may end with one; we end there too, with a warning)."""
        if self.percent_seen or self.words_seen:
            if not self.percent_seen:
                self.state.warn(lineno, "a % line that no % on the first line opened: the "
                                        "program ends here (LinuxCNC refuses it)")
            self.ended_by_percent = True
            return True
        self.percent_seen = True
        return False

    def _execute(self, line: Line, lineno: int) -> None:
        words = line.words
        if words and words[-1][0] == "O" and len(words) <= 2 and words[0][0] in "NO":
            # a bare O100 (or N10 O100): a numbered program starts here
            self._oword(read_oword(line.text, self.path, lineno), lineno)
            return
        if words:
            self.words_seen = True
            gs, ms, vals = self._classify(line, words, lineno)
            try:
                if ms and (98 in ms or 99 in ms):
                    self._subprogram(line, gs, ms, vals, lineno)
                    return
                if ms and M25_CODE in ms:
                    self.centroid.m25(gs, ms, vals, lineno)
                else:
                    if ms and (40 in ms or 41 in ms):
                        ms = self.mach3.probe_log(ms, lineno)
                    self.state.execute(gs, ms, vals, lineno)
                    self.mach3.after_line(lineno, self.params)
            except WordError as exc:
                raise self._error(line, lineno, exc.word, exc.message) from None
        if line.assigns:
            self._assign(line, lineno)

    def _subprogram(self, line: Line, gs: list[int], ms: list[int], vals: dict[str, float],
                    lineno: int) -> None:
        """An M98 or M99 line: it stands alone (LinuxCNC refuses other words with it)."""
        code = 98 if 98 in ms else 99
        others = [g_name(g) for g in gs] + [f"M{m}" for m in ms if m != code] + \
            [k for k in vals if k not in ("PL" if code == 98 else "")]
        if others:
            with_it = "P, L and N" if code == 98 else "N"
            raise WordError(f"M{code}", f"M{code} stands alone on its line, with {with_it} "
                                        f"only (LinuxCNC refuses {others[0]} with it)")
        if line.assigns:
            self._assign(line, lineno)
            line.assigns = None
        if code == 98:
            self.subprograms.m98(vals, lineno)
        else:
            self.subprograms.m99(lineno)

    def _classify(self, line: Line, words: list[tuple[str, str]], lineno: int
                  ) -> tuple[list[int], list[int], dict[str, float]]:
        gs: list[int] = []
        ms: list[int] = []
        vals: dict[str, float] = {}
        for i, (letter, text) in enumerate(words):
            if letter == "G":
                gs.append(self._g_code(line, i, text, lineno))
            elif letter == "M":
                ms.append(self._m_code(line, i, text, lineno))
            elif letter == "N":
                continue
            elif letter in vals:
                raise NcError(self.path, lineno, line.col(i), letter + text,
                              f"{letter} word given twice on one line")
            elif letter not in _VALUE_LETTERS:
                raise NcError(self.path, lineno, line.col(i), letter + text,
                              _unknown_letter(letter))
            else:
                vals[letter] = float(text)
        return gs, ms, vals

    def _g_code(self, line: Line, i: int, text: str, lineno: int) -> int:
        code = _G_CACHE.get(text)
        if code is not None:
            return code
        code = g_code10(float(text))
        word = "G" + text
        if code == G31_CODE10:
            return self.mach3.g31(lineno)  # not cached: each G31 line is noted
        if code is None:
            raise NcError(self.path, lineno, line.col(i), word, f"unknown G code {word}")
        if code in G_UNSUPPORTED:
            raise NcError(self.path, lineno, line.col(i), word,
                          f"{g_name(code)}: {G_UNSUPPORTED[code]}")
        if code not in G_GROUP:
            raise NcError(self.path, lineno, line.col(i), word, f"unknown G code {g_name(code)}")
        _G_CACHE[text] = code
        _G_BY_VALUE[float(text)] = code
        return code

    def _m_code(self, line: Line, i: int, text: str, lineno: int) -> int:
        code = _M_CACHE.get(text)
        if code is not None:
            return code
        number = float(text)
        if number in (98.0, 99.0, 40.0, 41.0, 25.0):  # M98/M99: _subprogram runs them;
            return int(number)  # M40/M41: see Mach3Probing; M25: CentroidCodes
        if number != int(number) or int(number) not in M_GROUP:
            raise NcError(self.path, lineno, line.col(i), "M" + text, m_refusal(number))
        _M_CACHE[text] = int(number)
        return int(number)

    def _error(self, line: Line, lineno: int, word: str, message: str) -> NcError:
        """NcError at the first word of the line named `word` ("X", "G5.2", "M3")."""
        for i, (letter, text) in enumerate(line.words):
            if word in (letter, _word_name(letter, text)):
                return NcError(self.path, lineno, line.col(i), letter + text, message)
        first = line.word_text(0) if line.words else ""
        return NcError(self.path, lineno, line.col(0), first, message)

    def _assign(self, line: Line, lineno: int) -> None:
        # LinuxCNC applies all settings of a line after reading it (the lexer evaluated them).
        params = self.params
        for key, value, col in line.assigns or ():
            try:
                if isinstance(key, str):
                    params.set_named(key, value)
                else:
                    params.set(key, value)
            except ParamError as exc:
                raise NcError(self.path, lineno, col, f"#{key}", str(exc)) from None


def _raw_lines(handle: TextIO, path: str) -> Iterator[str]:
    """Lines without their newline, read in chunks so that a huge line cannot fill memory."""
    rest = ""
    lineno = 0
    while True:
        try:
            chunk = handle.read(_CHUNK_CHARS)
        except (OSError, ValueError) as exc:
            raise NcError(path, lineno + 1, 0, "", f"cannot read program: {exc}") from exc
        if not chunk:
            break
        parts = (rest + chunk).split("\n")
        rest = parts.pop()
        lineno += len(parts)
        if len(rest) > MAX_LINE_CHARS:
            raise NcError(path, lineno + 1, MAX_LINE_CHARS + 1, "",
                          f"line longer than {MAX_LINE_CHARS} characters")
        yield from parts
    if rest:
        yield rest


def _first_lines(path: str, count: int) -> list[str]:
    """The program's first `count` lines, read again (M98 and M99 go back to earlier lines)."""
    with open(path, encoding="utf-8-sig", errors="replace", newline=None) as handle:
        return list(islice(_raw_lines(handle, path), count))


def _unknown_letter(letter: str) -> str:
    if letter in "ABCUVW":
        return f"axis {letter} is not supported (X Y Z only)"
    if letter == "O":
        return NO_KEYWORD
    if letter == "E":  # most often X1e3: G-code numbers have no exponent
        return "E words are not supported (nor exponents: write 1e3 as 1000)"
    return f"{letter} words are not supported"


def _word_name(letter: str, text: str) -> str:
    """Canonical name of a G or M word (G02 -> G2, G61.10 -> G61.1)."""
    if letter not in "GM" or text.startswith("#"):
        return letter + text
    code = g_code10(float(text))
    if code is None:
        return letter + text
    return g_name(code) if letter == "G" else f"M{code // 10}"


def program_nurbs(path: str, config: MachineConfig | None = None) -> list[Nurbs]:
    """Every NURBS block of the program as a Nurbs curve, in order (default machine config if
    none given): for benches, tests and tools."""
    cfg = config if config is not None else load_config(None)
    return [Nurbs.from_block(b) for b in read_program(path, cfg) if isinstance(b, NurbsBlock)]
