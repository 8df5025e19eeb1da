"""Checked reading of TOML tables (companion configs, replay scenarios).

Every value is read through one :class:`Table` method that states its type and range, so a
file is validated whole before any work starts.  Rules:

1. Numbers are finite (TOML allows ``nan`` and ``inf``) and in their stated range; booleans
   are not numbers.
2. A key nobody reads is an error that names the key and the closest known one: a misspelt
   ``takeof_delay_s`` must not silently fall back to its default.
3. Errors are :class:`TableError` (or the subclass the caller gives), one line that starts with
   where the value is: ``FILE: [link]: loss: 1.5 is out of range (must be below 1)``.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from companion.errors import CompanionError


class TableError(CompanionError):
    """A value of a TOML file is missing, of the wrong type, out of range or unknown."""


_MISSING = object()


def load_toml(path: str | Path, error: type[TableError] = TableError) -> dict[str, Any]:
    """The document of a TOML file, or ``error`` naming the file."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise error(f"{path}: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not TOML ({exc})") from None


class Table:
    """One TOML table read under the rules above; :meth:`finish` checks what was left."""

    def __init__(
        self, doc: dict[str, Any], where: str, error: type[TableError] = TableError
    ) -> None:
        self.doc = doc
        self.where = where
        self.error = error
        self.known: set[str] = set()
        self.children: list[Table] = []

    def fail(self, message: str, key: str | None = None) -> TableError:
        """The error to raise for ``key`` (or the whole table)."""
        where = f"{self.where}: {key}" if key else self.where
        return self.error(f"{where}: {message}")

    def _value(self, key: str, default: object) -> object:
        self.known.add(key)
        value = self.doc.get(key, default)
        if value is _MISSING:
            raise self.fail("required", key)
        return value

    def number(
        self,
        key: str,
        default: float | object = _MISSING,
        *,
        low: float | None = None,
        high: float | None = None,
        above: bool = False,
    ) -> float:
        """A finite number in [low, high] (``above``: low itself excluded)."""
        value = self._value(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(f"expected a number, got {value!r}", key)
        if not math.isfinite(value):
            raise self.fail(f"{value} is not a finite number", key)
        if low is not None and (value < low or (above and value == low)):
            raise self.fail(
                f"{value:g} is out of range (must be {'above' if above else 'at least'} {low:g})",
                key,
            )
        if high is not None and value > high:
            raise self.fail(f"{value:g} is out of range (must be at most {high:g})", key)
        return float(value)

    def integer(
        self,
        key: str,
        default: int | object = _MISSING,
        *,
        low: int | None = None,
        high: int | None = None,
    ) -> int:
        """An integer in [low, high]."""
        value = self._value(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"expected an integer, got {value!r}", key)
        if (low is not None and value < low) or (high is not None and value > high):
            span = f"{low if low is not None else '...'}..{high if high is not None else '...'}"
            raise self.fail(f"{value} is out of range ({span})", key)
        return value

    def optional_integer(self, key: str, **bounds: Any) -> int | None:
        """An integer that may be left out (None)."""
        self.known.add(key)
        return self.integer(key, **bounds) if key in self.doc else None

    def text(
        self,
        key: str,
        default: str | object = _MISSING,
        choices: Sequence[str] | None = None,
    ) -> str:
        """A non-empty string, one of ``choices`` if given."""
        value = self._value(key, default)
        if not isinstance(value, str) or not value:
            raise self.fail(f"expected a non-empty string, got {value!r}", key)
        if choices is not None and value not in choices:
            close = difflib.get_close_matches(value, choices, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise self.fail(f"{value!r} is not one of {', '.join(choices)}{hint}", key)
        return value

    def flag(self, key: str, default: bool | object = _MISSING) -> bool:
        value = self._value(key, default)
        if not isinstance(value, bool):
            raise self.fail(f"expected true or false, got {value!r}", key)
        return value

    def strings(self, key: str, default: Sequence[str] = ()) -> list[str]:
        value = self._value(key, list(default))
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.fail("expected a list of names", key)
        return list(value)

    def table(self, key: str) -> Table:
        """The sub-table ``[key]`` (empty if left out)."""
        value = self._value(key, {})
        if not isinstance(value, dict):
            raise self.fail("expected a table", key)
        child = Table(value, f"{self.where}: [{key}]", self.error)
        self.children.append(child)
        return child

    def has(self, key: str) -> bool:
        return key in self.doc

    def tables(self, key: str, label: str | None = None) -> list[Table]:
        """The array of tables ``[[key]]``, each named ``label N`` (from 1) in errors."""
        value = self._value(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(f"expected [[{key}]] tables", key)
        out = [
            Table(v, f"{self.where}: {label or key} {k}", self.error)
            for k, v in enumerate(value, start=1)
        ]
        self.children.extend(out)
        return out

    def finish(self) -> None:
        """Rule 2: every key of this table and its sub-tables was read."""
        for key in self.doc:
            if key not in self.known:
                close = difflib.get_close_matches(key, sorted(self.known), n=1, cutoff=0.6)
                hint = (
                    f"did you mean {close[0]!r}?"
                    if close
                    else f"known keys: {', '.join(sorted(self.known)) or 'none'}"
                )
                raise self.fail(f"unknown key {key!r} ({hint})")
        for child in self.children:
            child.finish()
