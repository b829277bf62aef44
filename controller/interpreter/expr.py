"""Values of G-code words as LinuxCNC reads them: numbers, parameters, [expressions], functions."""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from controller.interpreter.params import ParamError, Parameters

_NUMBER_RE = re.compile(r"[-+]?(?:\d{1,20}(?:\.\d{0,20})?|\.\d{1,20})", re.ASCII)
_SPACE_RE = re.compile(r"\s*", re.ASCII)
_NAME_RE = re.compile(r"[A-Z]+", re.ASCII)
_INDEX_TOLERANCE = 1e-4  # a parameter number given by a value must be this near an integer
EQUAL_TOLERANCE = 1e-4  # LinuxCNC's TOLERANCE_EQUAL: EQ and NE compare within it
MAX_DEPTH = 64  # nested brackets; deeper is refused (no recursion limit is ever reached)

# Binary operators and their precedence (LinuxCNC's interp_read.cc: higher binds first).
_BINARY: dict[str, int] = {
    "**": 6, "*": 5, "/": 5, "MOD": 5, "+": 4, "-": 4,
    "EQ": 3, "NE": 3, "GT": 3, "GE": 3, "LT": 3, "LE": 3, "AND": 2, "OR": 2, "XOR": 2,
}
_WORD_OPS = ("MOD", "EQ", "NE", "GT", "GE", "LT", "LE", "AND", "OR", "XOR")


class ExprError(Exception):
    """A value that cannot be read; `pos` is the 0-based column of the fault in the line."""

    def __init__(self, pos: int, message: str) -> None:
        super().__init__(message)
        self.pos = pos
        self.message = message


def _acos(v: float) -> float:
    if not -1.0 <= v <= 1.0:
        raise ValueError(f"ACOS of {v:g}: the argument must be in -1..1")
    return math.degrees(math.acos(v))


def _asin(v: float) -> float:
    if not -1.0 <= v <= 1.0:
        raise ValueError(f"ASIN of {v:g}: the argument must be in -1..1")
    return math.degrees(math.asin(v))


def _ln(v: float) -> float:
    if v <= 0.0:
        raise ValueError(f"LN of {v:g}: the argument must be positive")
    return math.log(v)


def _sqrt(v: float) -> float:
    if v < 0.0:
        raise ValueError(f"SQRT of {v:g}: the argument must not be negative")
    return math.sqrt(v)


def _round(v: float) -> float:
    # LinuxCNC rounds halves away from zero (Python's round() would round them to even).
    return float(math.floor(v + 0.5) if v >= 0.0 else -math.floor(-v + 0.5))


def _exp(v: float) -> float:
    try:
        return math.exp(v)
    except OverflowError:
        raise ValueError(f"EXP of {v:g} is too large") from None


# Angles are in degrees, as in LinuxCNC.
_UNARY: dict[str, Callable[[float], float]] = {
    "ABS": abs, "ACOS": _acos, "ASIN": _asin,
    "COS": lambda v: math.cos(math.radians(v)), "EXP": _exp,
    "FIX": lambda v: float(math.floor(v)), "FUP": lambda v: float(math.ceil(v)),
    "ROUND": _round, "LN": _ln, "SIN": lambda v: math.sin(math.radians(v)), "SQRT": _sqrt,
    "TAN": lambda v: math.tan(math.radians(v)),
}


class Reader:
    """Reads values from one upper-cased line against a parameter store."""

    def __init__(self, text: str, params: Parameters) -> None:
        self.text = text
        self.params = params

    def skip(self, pos: int) -> int:
        return _SPACE_RE.match(self.text, pos).end()  # type: ignore[union-attr]

    def value(self, pos: int, depth: int = 0) -> tuple[float, int]:
        """The real value at pos: a number, #parameter, [expression], FUNC[...] or a signed one."""
        text = self.text
        pos = self.skip(pos)
        if depth > MAX_DEPTH:
            raise ExprError(pos, f"expression nested deeper than {MAX_DEPTH} levels")
        ch = text[pos : pos + 1]
        if ch == "[":
            return self.bracket(pos, depth)
        if ch == "#":
            return self.parameter(pos, depth)
        if ch in ("-", "+") and not _NUMBER_RE.match(text, pos):
            v, end = self.value(pos + 1, depth + 1)
            return (-v if ch == "-" else v), end
        if ch.isalpha() and ch.isascii():
            return self.function(pos, depth)
        m = _NUMBER_RE.match(text, pos)
        if m is None:
            raise ExprError(pos, f"a number, #parameter or [expression] expected, found "
                                 f"{_found(text, pos)}")
        if m.end() < len(text) and text[m.end()] in "0123456789":
            raise ExprError(pos, "number too long (more than 20 digits)")
        return float(m.group(0)), m.end()

    def bracket(self, pos: int, depth: int) -> tuple[float, int]:
        """[ a op b op c ... ], evaluated by precedence, left to right within one level."""
        values: list[float] = []
        ops: list[str] = []
        v, pos = self.value(pos + 1, depth + 1)
        values.append(v)
        while True:
            pos = self.skip(pos)
            if self.text[pos : pos + 1] == "]":
                break
            op, op_pos = self._operator(pos), pos
            pos += len(op)
            while ops and _BINARY[ops[-1]] >= _BINARY[op]:
                _reduce(values, ops, op_pos)
            ops.append(op)
            v, pos = self.value(pos, depth + 1)
            values.append(v)
        while ops:
            _reduce(values, ops, pos)
        return values[0], pos + 1

    def _operator(self, pos: int) -> str:
        text = self.text
        if text.startswith("**", pos):
            return "**"
        if text[pos : pos + 1] in ("*", "/", "+", "-"):
            return text[pos]
        for op in _WORD_OPS:
            if text.startswith(op, pos):
                return op
        if pos >= len(text):
            raise ExprError(pos, "expression not closed: missing ']'")
        raise ExprError(pos, f"binary operator or ']' expected, found {_found(text, pos)}")

    def function(self, pos: int, depth: int) -> tuple[float, int]:
        m = _NAME_RE.match(self.text, pos)
        name = m.group(0) if m else ""
        end = m.end() if m else pos
        if name == "EXISTS":
            return self._exists(end, pos)
        if name not in _UNARY and name != "ATAN":
            raise ExprError(pos, f"unknown function or word {name!r} in a value")
        if self.text[self.skip(end) : self.skip(end) + 1] != "[":
            raise ExprError(end, f"{name} needs its argument in [ ]")
        arg, end = self.bracket(self.skip(end), depth + 1)
        if name == "ATAN":  # ATAN[y]/[x], two arguments, in degrees
            slash = self.skip(end)
            if self.text[slash : slash + 1] != "/" or \
                    self.text[self.skip(slash + 1) : self.skip(slash + 1) + 1] != "[":
                raise ExprError(slash, "ATAN needs two arguments: ATAN[y]/[x]")
            x, end = self.bracket(self.skip(slash + 1), depth + 1)
            return math.degrees(math.atan2(arg, x)), end
        try:
            return _UNARY[name](arg), end
        except ValueError as exc:
            raise ExprError(pos, str(exc)) from None

    def _exists(self, end: int, pos: int) -> tuple[float, int]:
        start = self.skip(end)
        inner = self.skip(start + 1)
        if self.text[start : start + 1] != "[" or self.text[inner : inner + 2] != "#<":
            raise ExprError(pos, "EXISTS needs a named parameter: EXISTS[#<name>]")
        name, after = self.name(inner + 1)
        close = self.skip(after)
        if self.text[close : close + 1] != "]":
            raise ExprError(close, "EXISTS[#<name>] not closed: missing ']'")
        return (1.0 if self.params.exists(name) else 0.0), close + 1

    def name(self, pos: int) -> tuple[str, int]:
        """The name of `<name>` at pos (spaces dropped, lower case, as LinuxCNC) and its end."""
        close = self.text.find(">", pos)
        if close < 0:
            raise ExprError(pos, "parameter name not closed: missing '>'")
        name = "".join(self.text[pos + 1 : close].split()).lower()
        if not name:
            raise ExprError(pos, "empty parameter name #<>")
        return name, close + 1

    def key(self, pos: int, depth: int = 0) -> tuple[int | str, int]:
        """The parameter after the `#` at pos: a number (from any value) or a name."""
        start = self.skip(pos + 1)
        if self.text[start : start + 1] == "<":
            return self.name(start)
        v, end = self.value(start, depth + 1)
        number = round(v)
        if abs(v - number) > _INDEX_TOLERANCE:
            raise ExprError(start, f"parameter number {v:g} is not an integer")
        return number, end

    def parameter(self, pos: int, depth: int) -> tuple[float, int]:
        key, end = self.key(pos, depth)
        try:
            if isinstance(key, str):
                return self.params.get_named(key), end
            return self.params.get(key), end
        except ParamError as exc:
            raise ExprError(pos, str(exc)) from None


def _found(text: str, pos: int) -> str:
    return repr(text[pos]) if pos < len(text) else "the end of the line"


def _reduce(values: list[float], ops: list[str], pos: int) -> None:
    b = values.pop()
    a = values.pop()
    values.append(_apply(ops.pop(), a, b, pos))


def _apply(op: str, a: float, b: float, pos: int) -> float:
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op in ("/", "MOD") and b == 0.0:
        raise ExprError(pos, f"division by zero ({a:g} {op} 0)")
    if op == "/":
        return a / b
    if op == "MOD":  # LinuxCNC makes the remainder non-negative ([-7 MOD 3] is 2)
        r = math.fmod(a, b)
        return r + abs(b) if r < 0.0 else r
    if op == "**":
        return _power(a, b, pos)
    return _compare(op, a, b)


def _power(a: float, b: float, pos: int) -> float:
    if a < 0.0 and b != math.floor(b):
        raise ExprError(pos, f"{a:g} ** {b:g}: a negative number to a non-integer power")
    if a == 0.0 and b < 0.0:
        raise ExprError(pos, f"0 ** {b:g}: division by zero")
    try:
        return math.pow(a, b)
    except OverflowError:
        raise ExprError(pos, f"{a:g} ** {b:g} is too large") from None


def _compare(op: str, a: float, b: float) -> float:
    result = {
        "EQ": abs(a - b) < EQUAL_TOLERANCE, "NE": abs(a - b) >= EQUAL_TOLERANCE,
        "GT": a > b, "GE": a >= b, "LT": a < b, "LE": a <= b,
        "AND": a != 0.0 and b != 0.0, "OR": a != 0.0 or b != 0.0,
        "XOR": (a != 0.0) != (b != 0.0),
    }[op]
    return 1.0 if result else 0.0
