"""Typed access to one table of a scene file: every error names the file, the key and what was
expected (README.md#scene-files: exit status 2 with a one-paragraph message, never a traceback)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from geometries.errors import InputError


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_finite_number(value: Any) -> bool:
    """A TOML int or float that is a finite float64 (an int such as 10**400 is not: it overflows)."""
    if not is_number(value):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def not_utf8(exc: UnicodeDecodeError) -> str:
    """The problem text for a file that is not UTF-8: which byte, where."""
    return f"not UTF-8 text: byte 0x{exc.object[exc.start]:02x} at byte offset {exc.start} cannot be decoded"


class SceneTable:
    """A TOML table of a scene file; keys are reported as `section.key` (as `key` for the section
    "": the keyword arguments of a function, e.g. :meth:`edem.scene.Scene.from_arrays`)."""

    def __init__(self, table: Any, scene_file: str | Path, section: str, allowed: Iterable[str] | None) -> None:
        self.scene_file = Path(scene_file)
        self.section = section
        if not isinstance(table, dict):
            raise InputError(f"[{section}] must be a table", file=self.scene_file, key=section, expected="a TOML table")
        self.table = table
        if allowed is not None:
            allowed = sorted(allowed)
            unknown = sorted(set(table) - set(allowed))
            if unknown:
                raise self.error(unknown[0], f"unknown key(s) {', '.join(map(repr, unknown))} in [{section}]", "one of " + ", ".join(allowed))

    def key(self, key: str) -> str:
        return f"{self.section}.{key}" if self.section else key

    def error(self, key: str, problem: str, expected: str | None = None) -> InputError:
        return InputError(problem, file=self.scene_file, key=self.key(key), expected=expected)

    def has(self, key: str) -> bool:
        return key in self.table

    def number(
        self,
        key: str,
        default: float | None = None,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        low: float | None = None,
        high: float | None = None,
        what: str = "a finite number",
    ) -> float:
        """A finite number (required unless a default is given), optionally > 0, >= 0 or in (low, high)."""
        if key not in self.table and default is None:
            raise self.error(key, f"[{self.section}] has no '{key}'", what)
        value = self.table.get(key, default)
        if not is_finite_number(value):
            raise self.error(key, f"got {value!r}", what)
        value = float(value)
        out_of_range = (positive and value <= 0) or (nonnegative and value < 0)
        if out_of_range or (low is not None and value <= low) or (high is not None and value >= high):
            raise self.error(key, f"{value:g} is out of range", what)
        return value

    def optional_number(self, key: str, **kw: Any) -> float | None:
        return self.number(key, **kw) if key in self.table else None

    def numbers(self, key: str, length: int | None = None, what: str = "a list of finite numbers") -> np.ndarray:
        value = self.table[key]
        if (
            not isinstance(value, list)
            or not all(is_finite_number(v) for v in value)
            or (length is not None and len(value) != length)
            or len(value) == 0
        ):
            raise self.error(key, f"got {value!r}", what)
        return np.array(value, dtype=np.float64)

    def triple(self, key: str, what: str = "3 finite numbers [x, y, z]") -> np.ndarray:
        return self.numbers(key, 3, what)

    def optional_triple(self, key: str, what: str = "3 finite numbers [x, y, z]") -> np.ndarray | None:
        return self.triple(key, what) if key in self.table else None

    def triples(self, key: str, n: int) -> np.ndarray:
        value = self.table[key]
        what = f"a list of {n} triples [[x, y, z], ...], one per time_s value"
        if not isinstance(value, list) or len(value) != n:
            got = f"{len(value)} entries" if isinstance(value, list) else repr(value)
            raise self.error(key, f"got {got}", what)
        for i, row in enumerate(value):
            if not (isinstance(row, list) and len(row) == 3 and all(is_finite_number(v) for v in row)):
                raise self.error(key, f"entry {i} is {row!r}", what)
        return np.array(value, dtype=np.float64)

    def string(self, key: str, default: str | None = None, choices: Iterable[str] | None = None) -> str:
        value = self.table.get(key, default)
        if not isinstance(value, str) or not value:
            raise self.error(key, f"got {value!r}", "a non-empty string")
        if choices is not None and value not in choices:
            raise self.error(key, f"'{value}' is not allowed", "one of " + ", ".join(choices))
        return value

    def strings(self, key: str, length: int) -> list[str]:
        value = self.table[key]
        if not (isinstance(value, list) and len(value) == length and all(isinstance(v, str) and v for v in value)):
            raise self.error(key, f"got {value!r}", f"a list of {length} column names (prefix '-' to negate)")
        return list(value)

    def boolean(self, key: str, default: bool) -> bool:
        value = self.table.get(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"got {value!r}", "true or false")
        return value

    def path(self, key: str, what: str) -> Path:
        path = Path(self.string(key))
        if not path.is_absolute():
            path = self.scene_file.parent / path
        try:
            found = path.is_file()
        except OSError as exc:  # e.g. a name longer than the file system allows
            raise self.error(key, f"cannot open {path}: {exc.strerror}", f"{what}, relative to the scene file") from None
        if not found:
            raise self.error(key, f"file not found: {path}", f"{what}, relative to the scene file")
        return path
