"""G-code lexer: one text line -> words (letter, number text) with lazily computed columns."""

from __future__ import annotations

import re

from controller.errors import NcError

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
_PARAM_REF_RE = re.compile(r"#\s*(\d{1,5})", re.ASCII)
_ASSIGN_RE = re.compile(r"#\s*(\d{1,5})\s*=\s*", re.ASCII)
_SPACE_RE = re.compile(r"\s*", re.ASCII)
_ASCII_UPPER = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")


def ascii_upper(raw: str) -> str:
    """Upper case for ASCII letters only (comments may hold any text; words never do)."""
    return raw.upper() if raw.isascii() else raw.translate(_ASCII_UPPER)


class Line:
    """The words of one program line; columns (1-based) are computed only when an error needs them.

    `words` holds (letter, number text) pairs; a number text may be `#N` (a parameter reference,
    then `has_params` is set). `assigns` holds `#N=value` settings, applied after the line.
    """

    __slots__ = ("words", "text", "cols", "assigns", "has_params")

    def __init__(self, words: list[tuple[str, str]], text: str, cols: list[int] | None = None,
                 assigns: list[tuple[int, str, int]] | None = None) -> None:
        self.words = words
        self.text = text
        self.cols = cols
        self.assigns = assigns
        self.has_params = cols is not None and any(t[0] == "#" for _, t in words)

    def col(self, index: int) -> int:
        """1-based column of word `index` (0 when the line has no such word)."""
        if self.cols is None:
            self.cols = [m.start() + 1 for m in WORD_RE.finditer(self.text)]
        return self.cols[index] if 0 <= index < len(self.cols) else 1

    def word_text(self, index: int) -> str:
        letter, number = self.words[index]
        return letter + number


def lex_line(raw: str, path: str, lineno: int) -> Line | str | None:
    """Lex one line (without its newline). Returns a Line, None for a skipped line, "%" for a
    percent delimiter line. Raises NcError for anything that is not RS274 words and comments."""
    if len(raw) > MAX_LINE_CHARS:
        raise NcError(path, lineno, MAX_LINE_CHARS + 1, "",
                      f"line longer than {MAX_LINE_CHARS} characters")
    text = ascii_upper(raw)
    if CLEAN_RE.fullmatch(text) is not None:  # the fast path: plain words, nothing else
        return Line(WORD_RE.findall(text), text)
    return _lex_slow(text, path, lineno)


def _lex_slow(text: str, path: str, lineno: int) -> Line | str | None:
    """Full scanner: comments, block delete, %, parameters, and precise error columns."""
    stripped = text.strip()
    if stripped == "%":
        return "%"
    if stripped.startswith("/"):
        return None  # block delete: the switch is always on in phcnc
    words: list[tuple[str, str]] = []
    cols: list[int] = []
    assigns: list[tuple[int, str, int]] = []
    pos, end = 0, len(text)
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
            pos = _lex_assign(text, pos, path, lineno, assigns)
        elif "A" <= ch <= "Z":
            pos = _lex_word(text, pos, path, lineno, words, cols)
        else:
            raise NcError(path, lineno, pos + 1, ch, f"unexpected character {_show(ch)}")
    return Line(words, text, cols, assigns or None)


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


def _lex_value(text: str, pos: int) -> re.Match[str] | None:
    """A number or a `#N` parameter reference at pos (after optional spaces)."""
    pos = _SPACE_RE.match(text, pos).end()  # type: ignore[union-attr]
    return _NUMBER_RE.match(text, pos) or _PARAM_REF_RE.match(text, pos)


def _lex_word(text: str, pos: int, path: str, lineno: int, words: list[tuple[str, str]],
              cols: list[int]) -> int:
    letter = text[pos]
    if letter == "O":
        raise NcError(path, lineno, pos + 1, "O", "O-words (subroutines, loops) are not supported")
    m = _lex_value(text, pos + 1)
    if m is None:
        bad = text[pos + 1 : pos + 2].strip() or "end of line"
        if bad == "[":
            raise NcError(path, lineno, pos + 1, letter,
                          "expressions in [ ] are not supported")
        raise NcError(path, lineno, pos + 1, letter, f"{letter} word without a number")
    value = m.group(0)
    if value.startswith("#"):
        value = "#" + m.group(1)
    elif m.end() < len(text) and text[m.end()] in "0123456789":
        raise NcError(path, lineno, pos + 1, letter, "number too long (more than 20 digits)")
    words.append((letter, value))
    cols.append(pos + 1)
    return m.end()


def _lex_assign(text: str, pos: int, path: str, lineno: int,
                assigns: list[tuple[int, str, int]]) -> int:
    m = _ASSIGN_RE.match(text, pos)
    value = _lex_value(text, m.end()) if m else None
    if m is None or value is None:
        raise NcError(path, lineno, pos + 1, "#",
                      "only '#N=number' parameter settings and '#N' references are supported")
    number = value.group(0)
    number = "#" + value.group(1) if number.startswith("#") else number
    assigns.append((int(m.group(1)), number, pos + 1))
    return value.end()
