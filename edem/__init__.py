"""Discrete element (DEM) and extended discrete element (EDEM) contact solver (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method, docs/method.md#4-viscoelastic-edem-thesis-chapter-6).

The Python face of the package::

    import edem

    scene = edem.load_scene("ideal-standing")          # a TOML file or a built-in scene
    result = edem.solve(scene, method="edem")           # every time point
    edem.write_results(result, "results/standing")      # summary.json, timeseries.csv, .vtp/.pvd

:meth:`Scene.from_arrays` builds a scene from meshes already in memory. Bad input raises
:class:`InputError` (a ValueError naming the file, key and expectation); a time point without
equilibrium raises :class:`SolverError`; :func:`solve` issues each of the run's warnings (the lines
``summary.json`` lists) as an :class:`EdemWarning`. Importing ``edem`` loads neither dolfinx, pyvista, VTK,
dask, matplotlib nor OpenSim.

The solver names load on first use (PEP 562), so that ``edem --help``, whose module lives in
this package, starts without numpy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from geometries.errors import InputError, SolverError

if TYPE_CHECKING:
    from edem.plausibility import EdemWarning
    from edem.results import RunResult, write_results
    from edem.scene import Scene, load_scene
    from edem.solver import solve

__version__ = "0.1.0"

#: public name -> the module defining it
_LAZY = {
    "EdemWarning": "edem.plausibility",
    "write_results": "edem.results",
    "Scene": "edem.scene",
    "load_scene": "edem.scene",
    "RunResult": "edem.results",
    "solve": "edem.solver",
}

__all__ = ["EdemWarning", "InputError", "RunResult", "Scene", "SolverError", "load_scene", "solve", "write_results"]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'edem' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
