"""O-word lines (LinuxCNC's subroutines and control flow): their label, keyword and arguments.

A bare `O100` line (nothing after it but a comment) starts a Fanuc-style numbered program
(LinuxCNC 2.9: its body runs up to `M99`, called by `M98 P100`); its keyword here is PROGRAM."""

from __future__ import annotations

import re
from dataclasses import dataclass

from controller.errors import NcError

KEYWORDS = frozenset((
    "SUB", "ENDSUB", "CALL", "RETURN", "IF", "ELSEIF", "ELSE", "ENDIF", "WHILE", "ENDWHILE",
    "DO", "REPEAT", "ENDREPEAT", "BREAK", "CONTINUE",
))
# Label and keyword of an O-word line, for scanning lines that are skipped (never raises).
_HEAD_RE = re.compile(r"\s*(?:N\s*\d+\s*)?O\s*(\d+|<[^>]*>)\s*([A-Z]*)", re.ASCII)
NO_KEYWORD = "an O-word needs a keyword (O100 sub, O100 if [...]) or a line of its own (O100)"
PROGRAM = "PROGRAM"  # the keyword of a bare `O100` line: a numbered program starts there
ASCII_UPPER = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")


@dataclass(slots=True, eq=False)
class OWord:
    """One O-word line: `O100 while [#1 LT 3]` has label "100", keyword "WHILE" and the
    argument text from `arg_pos` on (read when the line runs, against the parameters then)."""

    label: str  # "100" for O100 and O0100 alike, "<name>" (lower case, no spaces) for O<name>
    keyword: str
    arg_pos: int  # 0-based index in `text` where the arguments start
    text: str  # the upper-cased line
    col: int  # 1-based column of the O

    @property
    def name(self) -> str:
        if self.keyword == PROGRAM:
            return f"O{self.label}"
        return f"O{self.label} {self.keyword.lower()}"


def _label(raw: str) -> str:
    if raw.startswith("<"):
        return "<" + "".join(raw[1:-1].split()).lower() + ">"
    return str(int(raw))


def peek_oword(raw: str) -> tuple[str, str] | None:
    """(label, keyword) of a raw program line if it is an O-word line, else None."""
    m = _HEAD_RE.match(raw.translate(ASCII_UPPER))
    if m is None:
        return None
    return _label(m.group(1)), m.group(2) or PROGRAM


def read_oword(text: str, path: str, lineno: int) -> OWord:
    """The O-word of an upper-cased line; an NcError naming the O-word if it is malformed."""
    m = _HEAD_RE.match(text)
    col = text.index("O") + 1
    if m is None:
        raise NcError(path, lineno, col, "O",
                      "O-word without a label: O100 ... or O<name> ... (computed labels "
                      "O[...] are not supported)")
    label, keyword = _label(m.group(1)), m.group(2)
    word = f"O{label}"
    if not keyword:
        rest = text[m.end():].strip()
        if rest and not rest.startswith(("(", ";")):
            raise NcError(path, lineno, col, word, f"{word} is followed by {rest.split()[0]!r}, "
                                                   f"not by an O-word keyword (sub, call, if, "
                                                   f"while, ...)")
        return OWord(label, PROGRAM, m.end(), text, col)  # a numbered program starts here
    if keyword not in KEYWORDS:
        raise NcError(path, lineno, col, word,
                      f"unknown O-word keyword {keyword.lower()!r} (sub endsub call return if "
                      f"elseif else endif while endwhile do repeat endrepeat break continue)")
    return OWord(label, keyword, m.end(), text, col)
