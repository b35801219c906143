"""Typed reading of TOML tables that collects every problem before raising.

A :class:`TableReader` pulls fields out of one table, checks each against a rule and
records a problem (field path, value, rule) instead of raising, so that a scene with five
mistakes is reported once with all five.  Keys nobody asked for are reported as unknown.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from .errors import shown

_MISSING = object()


class Words(str):
    """A value described in words, shown without quotes: ``(from shape = 'chain')``."""

    def __repr__(self) -> str:
        return str(self)


class Problems:
    """An ordered list of human-readable problems, shared by all readers of one file."""

    def __init__(self) -> None:
        self.items: list[str] = []

    def add(self, field: str, value: Any, rule: str) -> None:
        text = "missing" if value is _MISSING else shown(value)
        self.items.append(f"`{field}` = {text}: {rule}")

    def __bool__(self) -> bool:
        return bool(self.items)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _finite(value: Any) -> bool:
    """A number that is a finite float: not a bool, inf or nan, nor an integer too large for a float."""
    if not _is_number(value):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer literal of 400 digits
        return False


class TableReader:
    """Read fields of one TOML table at ``path`` (``"bodies[0]"``, ``"simulation"``)."""

    def __init__(self, table: Any, path: str, problems: Problems, known: tuple[str, ...] = ()) -> None:
        self.path = path
        self.problems = problems
        if not isinstance(table, Mapping):
            problems.add(path, table, "must be a table")
            table = {}
        self.table = table
        self.used: set[str] = set(known)  # keys valid here even when not read

    def field(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        self.used.add(key)
        return self.table.get(key, default)

    def fail(self, key: str, value: Any, rule: str) -> None:
        self.problems.add(self.field(key), value, rule)

    def number(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        check: Callable[[float], bool] | None = None,
        rule: str = "",
    ) -> float | None:
        """A finite real number; ``check`` adds a rule such as positivity."""
        value = self.raw(key, default)
        if value is _MISSING:
            self.fail(key, value, "is required (a finite number)")
            return None
        if value is None:
            return None
        if not _finite(value):
            self.fail(key, value, "must be a finite number (a float: at most about 1.8e308)")
            return None
        if check is not None and not check(float(value)):
            self.fail(key, value, rule)
            return None
        return float(value)

    def integer(self, key: str, default: Any = _MISSING, *, minimum: int = 0, maximum: int | None = None,
                why: str = "") -> int | None:
        """An integer in ``[minimum, maximum]``; ``why`` explains the maximum."""
        value = self.raw(key, default)
        rule = f"an integer >= {minimum}" if maximum is None else f"an integer in [{minimum}, {maximum}]{why}"
        if value is _MISSING:
            self.fail(key, value, f"is required ({rule})")
            return None
        if value is None:
            return None
        if (
            not isinstance(value, int)
            or isinstance(value, bool)
            or value < minimum
            or (maximum is not None and value > maximum)
        ):
            self.fail(key, value, f"must be {rule}")
            return None
        return value

    def string(self, key: str, default: Any = _MISSING, *, choices: tuple[str, ...] = ()) -> str | None:
        value = self.raw(key, default)
        if value is _MISSING:
            rule = f"is required, one of {list(choices)}" if choices else "is required (a string)"
            self.fail(key, value, rule)
            return None
        if value is None:
            return None
        if not isinstance(value, str) or (choices and value not in choices):
            self.fail(key, value, f"must be one of {list(choices)}" if choices else "must be a string")
            return None
        return value

    def boolean(self, key: str, default: Any = _MISSING) -> bool | None:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            self.fail(key, value, "must be true or false")
            return None
        return value

    def vector(self, key: str, length: int, default: Any = _MISSING) -> tuple[float, ...] | None:
        """A list of ``length`` finite numbers."""
        value = self.raw(key, default)
        if value is _MISSING:
            self.fail(key, value, f"is required (a list of {length} finite numbers)")
            return None
        if value is None:
            return None
        if (
            not isinstance(value, (list, tuple))
            or len(value) != length
            or not all(_finite(v) for v in value)
        ):
            self.fail(key, value, f"must be a list of {length} finite numbers")
            return None
        return tuple(float(v) for v in value)

    def vectors(self, key: str, length: int, *, count: int | None = None) -> list[tuple[float, ...]] | None:
        """A list of vectors, each of ``length`` finite numbers (``count`` of them if given)."""
        value = self.raw(key)
        rule = f"must be a list of [{', '.join('x y z'.split()[:length])}] lists of finite numbers"
        if count is not None:
            rule += f", {count} of them"
        if (
            not isinstance(value, (list, tuple))
            or (count is not None and len(value) != count)
            or not all(
                isinstance(v, (list, tuple))
                and len(v) == length
                and all(_finite(x) for x in v)
                for v in value
            )
        ):
            self.fail(key, value, rule)
            return None
        return [tuple(float(x) for x in v) for v in value]

    def scalar_or_list(
        self, key: str, count: int | None, *, minimum: float, strict: bool, item: str = "item"
    ) -> list[float] | None:
        """One finite number for all ``count`` items, or a list of ``count`` of them.

        ``count`` None means the item count is unknown (an earlier field failed): only the
        values are checked.
        """
        value = self.raw(key)
        bound = f"> {minimum}" if strict else f">= {minimum}"
        how_many = f"{count} such numbers" if count is not None else "such numbers"
        rule = f"must be a finite number {bound}, or a list of {how_many} (one per {item})"
        values = [value] * (count or 1) if _is_number(value) else value
        if (
            not isinstance(values, (list, tuple))
            or (count is not None and len(values) != count)
            or not all(_finite(v) for v in values)
        ):
            self.fail(key, value, rule)
            return None
        bad = [v for v in values if (v <= minimum if strict else v < minimum)]
        if bad:
            self.fail(key, value, rule)
            return None
        return [float(v) for v in values]

    def finish(self) -> None:
        """Report keys of the table that no rule asked for."""
        unknown = sorted(set(self.table) - self.used)
        for key in unknown:
            self.fail(key, self.table[key], f"unknown key; valid keys here are {sorted(self.used)}")
