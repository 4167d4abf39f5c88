"""The user-facing errors, defined in :mod:`geometries.errors` (the lowest layer that raises them)."""

from geometries.errors import InputError, SolverError

__all__ = ["InputError", "SolverError"]
