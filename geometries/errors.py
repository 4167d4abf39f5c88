"""Errors the user can act on (README.md#command-line: exit status 2 on bad input, 1 on a failed check).

Defined in the lowest layer that raises them; :mod:`edem` re-exports them.
"""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad input: names the file, the key and what was expected (README.md#command-line, exit status 2).

    A ValueError, so code that guards against bad values catches it too.
    """

    def __init__(
        self,
        problem: str,
        *,
        file: str | Path | None = None,
        key: str | None = None,
        expected: str | None = None,
    ) -> None:
        self.problem = problem
        self.file = None if file is None else str(file)
        self.key = key
        self.expected = expected
        super().__init__(self.message())

    def message(self) -> str:
        where = []
        if self.file:
            where.append(self.file)
        if self.key:
            where.append(f"key '{self.key}'")
        text = (": ".join([", ".join(where), self.problem]) if where else self.problem)
        if self.expected:
            text += f" (expected {self.expected})"
        return text


class MeshWarning(UserWarning):
    """A repair or suspicion about an input mesh (flipped, dropped triangles, units...)."""


class SolverError(Exception):
    """A solve that cannot reach equilibrium; the message says why (no contact, singular system...)."""
