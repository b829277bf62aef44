"""G-code lexer: one text line -> words (letter, number text) with lazily computed columns."""

from __future__ import annotations

import math
import re

from controller.errors import NcError
from controller.interpreter.expr import ExprError, Reader
from controller.interpreter.owords import OWord, read_oword
from controller.interpreter.params import MAX_PARAMETER, Parameters

MAX_LINE_CHARS = 4096  # LinuxCNC allows 256; CAM output never needs more than this
_NUMBER = r"[-+]?(?:\d{1,20}(?:\.\d{0,20})?|\.\d{1,20})"  # no exponents (RS274), bounded size
# A line of plain words only (possessive: no backtracking, the check costs ~0.5 us a line).
CLEAN_RE = re.compile(
    r"\s*+(?:[A-Z]\s*+[-+]?+(?:\d{1,20}+(?:\.\d{0,20}+)?+|\.\d{1,20}+)\s*+)*+", re.ASCII)
# Splits a line that CLEAN_RE accepted: there every run of [-+.0-9] is exactly one number.
WORD_RE = re.compile(r"([A-Z])\s*([-+.\d]+)", re.ASCII)
# Every pattern is ASCII-only: Python's \d also matches other scripts' digits (X١٢ and X１２
# would read as X12), and str.upper() turns some non-ASCII letters into ASCII ones (long s).
_NUMBER_RE = re.compile(_NUMBER, re.ASCII)
_SPACE_RE = re.compile(r"\s*", re.ASCII)
_ASCII_UPPER = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")


def ascii_upper(raw: str) -> str:
    """Upper case for ASCII letters only (comments may hold any text; words never do)."""
    return raw.upper() if raw.isascii() else raw.translate(_ASCII_UPPER)


class Line:
    """The words of one program line; columns (1-based) are computed only when an error needs them.

    `words` holds (letter, number text) pairs, every value already evaluated (parameters and
    expressions are read when the line is lexed, against the store as it stands before the
    line). `assigns` holds the line's parameter settings (key, value, column), which LinuxCNC
    applies after the whole line has been read."""

    __slots__ = ("words", "text", "cols", "assigns")

    def __init__(self, words: list[tuple[str, str]], text: str, cols: list[int] | None = None,
                 assigns: list[tuple[int | str, float, int]] | None = None) -> None:
        self.words = words
        self.text = text
        self.cols = cols
        self.assigns = assigns

    def col(self, index: int) -> int:
        """1-based column of word `index` (0 when the line has no such word)."""
        if self.cols is None:
            self.cols = [m.start() + 1 for m in WORD_RE.finditer(self.text)]
        return self.cols[index] if 0 <= index < len(self.cols) else 1

    def word_text(self, index: int) -> str:
        letter, number = self.words[index]
        return letter + number


def lex_line(raw: str, path: str, lineno: int,
             params: Parameters | None = None) -> Line | OWord | str | None:
    """Lex one line (without its newline). Returns a Line, an OWord for an O-word line, None
    for a skipped line, "%" for a percent line. Values are read against `params` (an empty
    store if None). Raises NcError for anything that is not RS274/NGC words and comments."""
    if len(raw) > MAX_LINE_CHARS:
        raise NcError(path, lineno, MAX_LINE_CHARS + 1, "",
                      f"line longer than {MAX_LINE_CHARS} characters")
    text = ascii_upper(raw)
    if CLEAN_RE.fullmatch(text) is not None and "O" not in text:  # plain words, nothing else
        return Line(WORD_RE.findall(text), text)
    return _lex_slow(text, path, lineno, params if params is not None else Parameters())


def _lex_slow(text: str, path: str, lineno: int,
              params: Parameters) -> Line | OWord | str | None:
    """Full scanner: comments, block delete, %, O-words, parameters, expressions, columns."""
    stripped = text.strip()
    if stripped.startswith("%"):
        return "%"  # LinuxCNC reads nothing else on a percent line
    if stripped.startswith("/"):
        return None  # block delete: the switch is always on in phcnc
    if stripped.startswith("O") or (stripped.startswith("N") and _oword_after_n(stripped)):
        return read_oword(text, path, lineno)
    reader = Reader(text, params)
    words: list[tuple[str, str]] = []
    cols: list[int] = []
    assigns: list[tuple[int | str, float, int]] = []
    pos, end = 0, len(text)
    try:
        while pos < end:
            pos = _SPACE_RE.match(text, pos).end()  # type: ignore[union-attr]
            if pos >= end:
                break
            ch = text[pos]
            if ch == ";":
                break
            if ch == "(":
                pos = _skip_comment(text, pos, path, lineno)
            elif ch == "#":
                pos = _lex_assign(reader, pos, path, lineno, assigns)
            elif "A" <= ch <= "Z" or ch in "@^":  # @ ^: polar radius and angle
                pos = _lex_word(reader, pos, path, lineno, words, cols)
            else:
                raise NcError(path, lineno, pos + 1, ch, f"unexpected character {_show(ch)}")
    except ExprError as exc:
        raise NcError(path, lineno, exc.pos + 1, text[exc.pos : exc.pos + 1].strip(),
                      exc.message) from None
    return Line(words, text, cols, assigns or None)


def _oword_after_n(stripped: str) -> bool:
    """`N10 O100 sub`: an O-word after a line number."""
    m = re.match(r"N\s*\d+\s*O", stripped, re.ASCII)
    return m is not None


def _show(ch: str) -> str:
    return repr(ch) if ch.isprintable() else f"U+{ord(ch):04X}"


def _skip_comment(text: str, pos: int, path: str, lineno: int) -> int:
    close = text.find(")", pos + 1)
    if close < 0:
        raise NcError(path, lineno, pos + 1, "(", "comment not closed: missing ')'")
    nested = text.find("(", pos + 1, close)
    if nested >= 0:
        raise NcError(path, lineno, nested + 1, "(", "nested comment: '(' inside a comment")
    return close + 1


def _lex_word(reader: Reader, pos: int, path: str, lineno: int, words: list[tuple[str, str]],
              cols: list[int]) -> int:
    text = reader.text
    letter = text[pos]
    if letter == "O":
        raise NcError(path, lineno, pos + 1, "O",
                      "an O-word must stand first on its line (O100 sub, O100 if [...])")
    start = reader.skip(pos + 1)
    m = _NUMBER_RE.match(text, start)
    if m is not None:
        if m.end() < len(text) and text[m.end()] in "0123456789":
            raise NcError(path, lineno, pos + 1, letter, "number too long (more than 20 digits)")
        value_text, end = m.group(0), m.end()
    else:
        if start >= len(text) or not (text[start] in "[#+-" or "A" <= text[start] <= "Z"):
            raise NcError(path, lineno, pos + 1, letter, f"{letter} word without a number")
        try:
            value, end = reader.value(start)
        except ExprError as exc:
            if exc.pos == start and text[start].isalpha():
                raise NcError(path, lineno, pos + 1, letter,
                              f"{letter} word without a number") from None
            raise NcError(path, lineno, pos + 1, letter + text[start : exc.pos + 1].strip(),
                          f"{letter} word: {exc.message}") from None
        if not math.isfinite(value):
            raise NcError(path, lineno, pos + 1, letter, f"{letter} word: the value is not finite")
        value_text = repr(value)
    words.append((letter, value_text))
    cols.append(pos + 1)
    return end


def _lex_assign(reader: Reader, pos: int, path: str, lineno: int,
                assigns: list[tuple[int | str, float, int]]) -> int:
    """`#N = value`, `#<name> = value` or `#[expr] = value`; stored after the line."""
    try:
        key, end = reader.key(pos)
    except ExprError as exc:
        raise ExprError(exc.pos, f"parameter setting: {exc.message}") from None
    eq = reader.skip(end)
    if reader.text[eq : eq + 1] != "=":
        raise NcError(path, lineno, pos + 1, "#",
                      "a parameter setting needs '=': #1 = 2, #<depth> = [#1 * 2]")
    if isinstance(key, int) and not 1 <= key <= MAX_PARAMETER:
        raise NcError(path, lineno, pos + 1, f"#{key}",
                      f"parameter #{key} out of range 1..{MAX_PARAMETER}")
    value, end = reader.value(eq + 1)
    if not math.isfinite(value):
        raise NcError(path, lineno, pos + 1, "#", "the value set is not finite")
    assigns.append((key, value, pos + 1))
    return end
