"""The FE stack (dolfinx, PETSc, ufl, basix, MPI), imported on first use.

Importing :mod:`fem_reference` does not import dolfinx: every module that needs the FE stack
calls :func:`fe_modules` inside the function that needs it. The PETSc helpers shared by the
solvers (:mod:`fem_reference.contact`, :mod:`fem_reference.contact_vi`) live here too.
"""

from __future__ import annotations

import itertools
from typing import Any

_counter = itertools.count()


def fe_modules() -> dict[str, Any]:
    """The FE stack, imported in the order the wheel requires: keys ``dolfinx``, ``fem``,
    ``fem_petsc``, ``la``, ``ufl``, ``basix_ufl``, ``MPI``, ``PETSc``.

    Raises ImportError without the ``fe`` extra."""
    import dolfinx_solver  # noqa: F401  (must precede dolfinx / petsc4py)
    import basix.ufl
    import dolfinx
    import dolfinx.fem
    import dolfinx.fem.petsc
    import dolfinx.la
    import dolfinx.mesh
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    return {"dolfinx": dolfinx, "fem": dolfinx.fem, "fem_petsc": dolfinx.fem.petsc,
            "la": dolfinx.la, "ufl": ufl, "basix_ufl": basix.ufl, "MPI": MPI, "PETSc": PETSc}


def options_prefix(stem: str) -> str:
    """A PETSc options prefix no other solve of this process uses (``stem`` + a counter + ``_``):
    each solve's options stay its own."""
    return f"{stem}{next(_counter)}_"


def snes_reason_name(PETSc: Any, reason: int) -> str:
    """The name of a SNES converged reason (``CONVERGED_FNORM_RELATIVE``, ``DIVERGED_MAX_IT``...)."""
    for name in dir(PETSc.SNES.ConvergedReason):
        if not name.startswith("_") and getattr(PETSc.SNES.ConvergedReason, name) == reason:
            if name.startswith(("CONVERGED", "DIVERGED")) or name == "ITERATING":
                return name
    return str(reason)
