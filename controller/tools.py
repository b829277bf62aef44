"""The tool table in LinuxCNC's tool.tbl format (T, P, Z, D, ; comment) and its file.

One line per tool: `T1 P1 Z12.5 D6 ; 6 mm end mill`. T is the tool number (1 or more; T0 is
"no tool" and has no line), P its pocket, Z its length and D its diameter, in mm; the text after
`;` is the comment. The file is read strictly: another word, a repeated tool, a bad number or a
file over MAX_FILE_BYTES is a ToolTableError naming the file, the line and the word.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, replace
from typing import Any

from controller.errors import CncError
from controller.table_file import read_capped, write_atomic

MAX_FILE_BYTES = 1 << 20  # a table of a thousand tools is 50 kB; anything larger is not one
MAX_TOOL = 99999  # LinuxCNC's CANON_POCKETS_MAX is far smaller; a larger T is a typo
MAX_LENGTH_MM = 1000.0  # a tool longer than a metre is a typo, not a tool
_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


class ToolTableError(CncError):
    """The tool table cannot be read, or a line of it is wrong: names the file (and line)."""

    def __init__(self, path: str, message: str, line: int | None = None) -> None:
        self.path = path
        self.line = line
        self.message = message
        where = path if line is None else f"{path}:{line}"
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True, slots=True)
class Tool:
    """One line of the table: tool number, pocket, length and diameter (mm), comment."""

    number: int
    pocket: int
    length_mm: float = 0.0
    diameter_mm: float = 0.0
    comment: str = ""

    def line(self) -> str:
        """The tool.tbl line of this tool."""
        text = f"T{self.number} P{self.pocket} Z{_num(self.length_mm)} D{_num(self.diameter_mm)}"
        return f"{text} ;{self.comment}" if self.comment else text

    def describe(self) -> dict[str, Any]:
        return {"tool": self.number, "pocket": self.pocket, "length_mm": self.length_mm,
                "diameter_mm": self.diameter_mm, "comment": self.comment}


def _num(value: float) -> str:
    return f"{value:.6f}".rstrip("0").rstrip(".") if value else "0"


@dataclass(frozen=True, slots=True)
class ToolTable:
    """Tools by number (immutable: with_tool and without return new tables)."""

    tools: tuple[Tool, ...] = ()

    def get(self, number: int) -> Tool | None:
        for tool in self.tools:
            if tool.number == number:
                return tool
        return None

    def length_mm(self, number: int) -> float:
        """Tool length of `number`; T0 (no tool) has none; KeyError if not in the table."""
        if number == 0:
            return 0.0
        tool = self.get(number)
        if tool is None:
            raise KeyError(number)
        return tool.length_mm

    def with_tool(self, tool: Tool) -> ToolTable:
        check_tool(tool)
        others = [t for t in self.tools if t.number != tool.number]
        return ToolTable(tuple(sorted([*others, tool], key=lambda t: t.number)))

    def without(self, number: int) -> ToolTable:
        if self.get(number) is None:
            raise KeyError(number)
        return ToolTable(tuple(t for t in self.tools if t.number != number))

    def text(self) -> str:
        return "".join(t.line() + "\n" for t in self.tools)

    def describe(self) -> list[dict[str, Any]]:
        return [t.describe() for t in self.tools]


def check_tool(tool: Tool) -> None:
    """ValueError naming what is wrong with a tool's fields."""
    if not 1 <= tool.number <= MAX_TOOL:
        raise ValueError(f"tool number T{tool.number} must be 1..{MAX_TOOL}")
    if not 0 <= tool.pocket <= MAX_TOOL:
        raise ValueError(f"pocket P{tool.pocket} must be 0..{MAX_TOOL}")
    if not (math.isfinite(tool.length_mm) and abs(tool.length_mm) <= MAX_LENGTH_MM):
        raise ValueError(f"length Z{tool.length_mm} must be within +-{MAX_LENGTH_MM:g} mm")
    if not (math.isfinite(tool.diameter_mm) and 0 <= tool.diameter_mm <= MAX_LENGTH_MM):
        raise ValueError(f"diameter D{tool.diameter_mm} must be 0..{MAX_LENGTH_MM:g} mm")
    if "\n" in tool.comment or "\r" in tool.comment:
        raise ValueError("a comment is one line")


def parse_tool_line(text: str) -> Tool | None:
    """One tool.tbl line as a Tool (None: blank or comment only); ValueError naming the word."""
    body, _, comment = text.partition(";")
    words: dict[str, float] = {}
    rest = _WORD.sub(lambda m: _take(m, words), body).strip()
    if rest:
        raise ValueError(f"cannot read {rest.split()[0]!r}: a line is T P Z D words and "
                         "a ; comment")
    if not words:
        return None  # a blank line or a comment alone
    if "T" not in words:
        raise ValueError("a tool line needs T (the tool number)")
    for letter in ("T", "P"):
        if letter in words and words[letter] != int(words[letter]):
            raise ValueError(f"{letter}{words[letter]:g} must be a whole number")
    tool = Tool(int(words["T"]), int(words.get("P", words["T"])), words.get("Z", 0.0),
                words.get("D", 0.0), comment.strip())
    check_tool(tool)
    return tool


def _take(match: re.Match[str], words: dict[str, float]) -> str:
    letter = match.group(1).upper()
    if letter not in "TPZD":
        raise ValueError(f"{letter} word: phcnc keeps T, P, Z and D of a tool.tbl line "
                         "(X Y A B C U V W I J Q offsets are not supported)")
    if letter in words:
        raise ValueError(f"two {letter} words on one line")
    words[letter] = float(match.group(2))
    return ""


def parse_tool_table(text: str, path: str) -> ToolTable:
    """A whole tool.tbl text; ToolTableError naming the file, line and what is wrong."""
    seen: dict[int, int] = {}
    tools = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        try:
            tool = parse_tool_line(raw)
        except ValueError as exc:
            raise ToolTableError(path, str(exc), lineno) from None
        if tool is None:
            continue
        if tool.number in seen:
            raise ToolTableError(path, f"T{tool.number} is already on line "
                                       f"{seen[tool.number]}", lineno)
        seen[tool.number] = lineno
        tools.append(tool)
    return ToolTable(tuple(sorted(tools, key=lambda t: t.number)))


def load_tool_table(path: str | os.PathLike[str], missing_ok: bool = True) -> ToolTable:
    """The table kept in `path`; an empty table when it does not exist and missing_ok (the
    daemon's own state: none kept yet). A file a user named must exist."""
    name = os.fspath(path)
    raw = read_capped(name, MAX_FILE_BYTES, ("tool table", "a tool table"), ToolTableError,
                      missing_ok)
    if raw is None:
        return ToolTable()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ToolTableError(name, f"not a tool table: {exc}") from exc
    return parse_tool_table(text, name)


def save_tool_table(path: str | os.PathLike[str], table: ToolTable) -> None:
    """Write the table atomically (temporary file, fsync, os.replace): a crash leaves the old
    table or the new one, never half of one."""
    write_atomic(os.fspath(path), table.text(), ".tool-", "tool table", ToolTableError)


@dataclass(frozen=True, slots=True)
class ToolsConfig:
    """The `tools` section: where M6 changes tools and which table is in force.

    change_position_mm: machine X Y Z of the manual tool change (None: change where the tool
    stands, as LinuxCNC without TOOL_CHANGE_POSITION). table_file: the tool.tbl of embedded
    runs (cncd keeps its own, `cncctl tool`). table: the table in force, read from table_file
    when the config is loaded, or put in by cncd for a job."""

    change_position_mm: tuple[float, ...] | None = None
    table_file: str | None = None
    table: ToolTable | None = None  # None: no table in force (T unchecked, lengths zero)

    def with_table(self, table: ToolTable) -> ToolsConfig:
        return replace(self, table=table)


def read_tools_section(sec: Any, axis_names: tuple[str, ...],
                       travel_mm: tuple[tuple[float, float], ...]) -> ToolsConfig:
    """The `tools` section of a config (a yaml_strict Section): change_position_mm within each
    axis's travel, table_file relative to the config's folder, read at once."""
    from controller.errors import ConfigError

    position = None
    if "change_position_mm" in sec.data:
        raw = sec._raw("change_position_mm", None)
        if not isinstance(raw, list) or len(raw) != len(axis_names):
            raise ConfigError(sec.path, sec._key("change_position_mm"),
                              f"must be a list of {len(axis_names)} numbers "
                              f"({', '.join(axis_names)})")
        position = tuple(sec._check_float("change_position_mm", v, None, lo, hi)
                         for v, (lo, hi) in zip(raw, travel_mm, strict=True))
    table_file = sec._raw("table_file", None)
    table = None
    if table_file is not None:
        if not isinstance(table_file, str) or not table_file:
            raise ConfigError(sec.path, sec._key("table_file"), "must be a file name")
        table_file = os.path.join(os.path.dirname(os.path.abspath(sec.path)), table_file)
        try:
            table = load_tool_table(table_file, missing_ok=False)
        except ToolTableError as exc:
            raise ConfigError(sec.path, sec._key("table_file"), str(exc)) from None
    sec.finish()
    return ToolsConfig(position, table_file, table)
