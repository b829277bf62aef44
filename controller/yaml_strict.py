"""Strict YAML reading: a mapping at a time, every key used, none given twice (klippy style)."""

from __future__ import annotations

import math
from typing import Any

import yaml

from controller.errors import ConfigError

REQUIRED = object()  # a key without a default


class Section:
    """Reads one mapping; every key must be consumed, so unknown keys are errors."""

    def __init__(self, data: Any, path: str, prefix: str) -> None:
        if not isinstance(data, dict):
            raise ConfigError(path, prefix or "<top>", "must be a mapping")
        self.data = data
        self.path = path
        self.prefix = prefix
        self.used: set[str] = set()

    def _key(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def _raw(self, key: str, default: Any) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is REQUIRED:
                typo = close_match(key, [k for k in self.data if k not in self.used])
                if typo is not None:  # name the key as written, not only the one missing
                    raise ConfigError(self.path, self._key(typo), f"unknown key (did you "
                                                                  f"mean {key}?)")
                raise ConfigError(self.path, self._key(key), "is required")
            return default
        return self.data[key]

    def float(self, key: str, default: Any = REQUIRED, *, above: float | None = None,
              minval: float | None = None, maxval: float | None = None) -> float:
        value = self._raw(key, default)
        return self._check_float(key, value, above, minval, maxval)

    def _check_float(self, key: str, value: Any, above: float | None, minval: float | None,
                     maxval: float | None) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            hint = ""
            if isinstance(value, str) and number_text(value):
                hint = " (YAML reads 1e3 as text: write 1.0e+3)"
            raise ConfigError(self.path, self._key(key), f"must be a number, got {value!r}{hint}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(self.path, self._key(key), "must be finite")
        if above is not None and value <= above:
            raise ConfigError(self.path, self._key(key), f"must be > {above}, got {value}")
        if minval is not None and value < minval:
            raise ConfigError(self.path, self._key(key), f"must be >= {minval}, got {value}")
        if maxval is not None and value > maxval:
            raise ConfigError(self.path, self._key(key), f"must be <= {maxval}, got {value}")
        return value

    def int(self, key: str, default: Any = REQUIRED, *, minval: int, maxval: int) -> int:
        value = self._raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(self.path, self._key(key), f"must be an integer, got {value!r}")
        if not minval <= value <= maxval:
            raise ConfigError(self.path, self._key(key), f"must be in [{minval}, {maxval}]")
        return value

    def str(self, key: str, default: Any = REQUIRED, *, choices: tuple[str, ...] = ()) -> str:
        value = self._raw(key, default)
        if not isinstance(value, str):
            raise ConfigError(self.path, self._key(key), f"must be a string, got {value!r}")
        if choices and value not in choices:
            raise ConfigError(self.path, self._key(key), f"must be one of {', '.join(choices)}")
        return value

    def bool(self, key: str, default: Any = REQUIRED) -> bool:
        value = self._raw(key, default)
        if not isinstance(value, bool):
            raise ConfigError(self.path, self._key(key), f"must be true or false, got {value!r}")
        return value

    def names(self, key: str) -> tuple[str, ...]:
        value = self._raw(key, [])
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise ConfigError(self.path, self._key(key), "must be a list of names")
        return tuple(value)

    def range(self, key: str) -> tuple[float, float]:
        value = self._raw(key, REQUIRED)
        if not isinstance(value, list) or len(value) != 2:
            raise ConfigError(self.path, self._key(key), "must be a list [min, max]")
        lo = self._check_float(key, value[0], None, None, None)
        hi = self._check_float(key, value[1], None, None, None)
        if lo >= hi:
            raise ConfigError(self.path, self._key(key), "min must be below max")
        return lo, hi

    def section(self, key: str, default: Any = REQUIRED) -> Section:
        return Section(self._raw(key, default), self.path, self._key(key))

    def mapping(self, key: str, default: Any = REQUIRED) -> dict[str, Any]:
        value = self._raw(key, default)
        if not isinstance(value, dict):
            raise ConfigError(self.path, self._key(key), "must be a mapping")
        return value

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            near = close_match(unknown[0], list(self.used))
            raise ConfigError(self.path, self._key(str(unknown[0])), "unknown key" + (
                f" (did you mean {near}?)" if near is not None else ""))


def close_match(key: Any, candidates: list[Any]) -> Any:
    """The candidate a mistyped key most likely meant, if one is close."""
    import difflib  # only on the error path: a valid config never pays its import

    names = [c for c in candidates if isinstance(c, str)]
    found = difflib.get_close_matches(key, names, n=1, cutoff=0.8) if isinstance(key, str) \
        else []
    return found[0] if found else None


def number_text(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


MAX_NODES = 20_000  # a machine config has a few hundred; aliases counted as what they expand to
MAX_DEPTH = 32


class StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping (PyYAML keeps the last one:
    a second `max_feed_mm_s:` further down would silently win), a key that is not a plain
    scalar, and a document larger or deeper than a config can be once its aliases are
    expanded (a 1.4 kB "billion laughs" grew to gigabytes), before building anything."""

    def construct_document(self, node: yaml.Node) -> Any:
        size = _expanded_size(node, {}, 0)
        if size > MAX_NODES:
            raise yaml.constructor.ConstructorError(
                None, None, f"{size:.3g} values once its aliases are expanded (at most "
                f"{MAX_NODES}): not a machine configuration", node.start_mark)
        return super().construct_document(node)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise yaml.constructor.ConstructorError(
                    "while reading a mapping", node.start_mark,
                    "a key must be a name or a number, not a list or mapping",
                    key_node.start_mark)
            key = self.construct_object(key_node, deep=True)  # type: ignore[no-untyped-call]
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    "while reading a mapping", node.start_mark,
                    f"the key {key!r} is given twice", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _expanded_size(node: yaml.Node, memo: dict[int, float], depth: int) -> float:
    """Values under node with every alias expanded (an alias is the node it names, so it is
    counted once per use; memo keeps this linear in the text)."""
    if depth > MAX_DEPTH:
        raise yaml.constructor.ConstructorError(
            None, None, f"nested more than {MAX_DEPTH} levels deep: not a machine "
            "configuration", node.start_mark)
    known = memo.get(id(node))
    if known is not None:
        return known
    if isinstance(node, yaml.MappingNode):
        children = [n for pair in node.value for n in pair]
    elif isinstance(node, yaml.SequenceNode):
        children = list(node.value)
    else:
        children = []
    size = 1.0 + sum(_expanded_size(child, memo, depth + 1) for child in children)
    memo[id(node)] = size
    return size
