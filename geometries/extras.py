"""The optional parts of the install (pyproject.toml's extras) and the error that names the one
to install.

The solver and its scenes need only numpy, scipy, meshio, embreex and tomli-w. Everything else is
an extra, imported inside the function that needs it: a missing one is an :class:`MissingExtra`
(an InputError, exit status 2 on the command line) that says what to install, not an ImportError
traceback.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from geometries.errors import InputError

__all__ = ["EXTRA_OF_MODULE", "MissingExtra", "extra_of", "import_extra"]

#: top-level module -> the extra (pyproject.toml) that installs it
EXTRA_OF_MODULE = {
    "vtk": "vtk", "vtkmodules": "vtk",
    "pyvista": "render", "matplotlib": "render",
    "dask": "campaigns", "distributed": "campaigns", "tqdm": "campaigns",
    "gmsh": "gmsh",
    "dolfinx": "fe", "dolfinx_solver": "fe", "petsc4py": "fe", "mpi4py": "fe", "ufl": "fe", "basix": "fe",
    "opensim": "opensim",
}


class MissingExtra(InputError):
    """An optional package is not installed: names it and the extra that installs it."""

    def __init__(self, module: str, extra: str, purpose: str) -> None:
        self.module, self.extra = module, extra
        super().__init__(f"{purpose} needs the optional package '{module}', which is not installed",
                         expected=f"the `{extra}` extra: pip install 'edem[{extra}]'")


def extra_of(error: ImportError) -> str | None:
    """The extra whose package ``error`` found missing (None: not an optional package)."""
    name = getattr(error, "name", None) or ""
    return EXTRA_OF_MODULE.get(name.split(".")[0])


def import_extra(module: str, purpose: str) -> ModuleType:
    """``importlib.import_module(module)``; a missing optional package is a :class:`MissingExtra`
    saying that ``purpose`` needs it."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        extra = extra_of(exc)
        if extra is None:
            raise
        raise MissingExtra(exc.name.split(".")[0], extra, purpose) from None
