"""Size of an FE reference run before it is meshed: cells, DOFs, memory, and whether it fits.

The cartilage solids of :mod:`geometries.fe_solids` are M's candidate surface, midpoint-refined
until its edges are about the mesh size, extruded through the thickness in layers and split into
tetrahedra (3 per prism). Their cell and vertex counts follow from the surface alone, so a run
can be sized, and refused, before gmsh or dolfinx allocate anything (``edem fe --mesh-size
0.01`` once asked for 75 GiB).

Memory: a fixed cost for the loaded libraries plus a per-DOF cost, calibrated on this project's
ideal-ankle slab (P2) on the 2-core development machine (peak resident set, ``/usr/bin/time``):

=============  =======  =================
mesh size      DOFs     peak RSS
=============  =======  =================
1.0 mm         71,011   1.06 GB (direct)
0.7 mm         401,506  8.5 GB (direct; the estimate: 317k DOFs, 4.9 GB)
=============  =======  =================

and on the subject-like ankle's slab at 0.7 mm 532k DOFs, 11 GB by LU (estimated 419k, 7.0 GB;
``fe-convergence``, docs/campaigns.md): past one midpoint refinement the counts run 20-30 % low
and the memory 1.6-1.7x, which the x2 margin covers.

The direct solver's (MUMPS LU) factor grows like N^(4/3) for 3D meshes (nested dissection) and is
scaled from that point; the Krylov solver's (p-multigrid) memory grows like N, a measured cost per
DOF (:data:`ITERATIVE_BYTES_PER_DOF`). The estimate is doubled as a safety margin before it is
compared with the memory available. The Krylov path is the default from
:data:`ITERATIVE_FROM_DOFS` unknowns for P2 and Taylor-Hood (:func:`iterative_is_default`), where
it is the faster.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from geometries.errors import InputError

#: resident memory of Python with dolfinx, PETSc, gmsh and VTK loaded, bytes (measured ~0.45 GB)
BASE_BYTES = 450e6
#: calibration point (see the module docstring): DOFs and the memory above BASE_BYTES, bytes
_CALIBRATION_DOFS = 71_011
_CALIBRATION_BYTES = 1.06e9 - BASE_BYTES
#: factor between the estimate and what must be available (the calibration is one machine, one mesh)
SAFETY = 2.0
#: The Krylov path's memory per DOF above BASE_BYTES, bytes: measured 2026-11-28 (peak resident
#: set) on the subject-like ankle at 0.7 mm, Taylor-Hood at nu 0.499 (556k DOFs, 2.6 GB: 3.9 kB);
#: P2 there 532k DOFs, 1.7 GB (2.3 kB); P2 at 1.0 mm 94k DOFs, 0.44 GB.
ITERATIVE_BYTES_PER_DOF = 4.0e3
#: From this many unknowns ``auto`` takes the Krylov path even where the LU fits: measured
#: 2026-11-28 (CPU time of ``edem fe``, the ideal ankle) P1 10k DOFs 1.9 s by LU, 2.1 s Krylov;
#: P1 71k 20 s, 15 s; P2 39k 5.7 s, 4.5 s; Taylor-Hood 42k 8.3 s, 6.8 s and 74k 26 s, 12 s; the
#: subject-like ankle P2 94k 25 s, 14 s (docs/method.md, section 6, "Linear solver").
ITERATIVE_FROM_DOFS = 20_000


@dataclass(frozen=True)
class FESize:
    """Estimated size of one FE solve."""

    cells: int
    vertices: int
    dofs: int
    solver: str  # "direct" | "iterative"
    memory_bytes: float  # peak resident estimate, before the safety factor


def solid_size(n_surface_triangles: int, surface_mean_edge_mm: float, max_thickness_mm: float,
               mesh_size_mm: float, layers: int | None) -> tuple[int, int]:
    """(cells, vertices) of the extruded solid of :mod:`geometries.fe_solids` (same refinement
    and layering rules): levels = ceil(log2(edge / size)), layers = ceil(thickness / size)."""
    levels = max(0, math.ceil(math.log2(surface_mean_edge_mm / mesh_size_mm) - 1e-9)) if surface_mean_edge_mm > mesh_size_mm else 0
    n_layers = int(layers) if layers is not None else max(1, math.ceil(max_thickness_mm / mesh_size_mm - 1e-9))
    triangles = n_surface_triangles * 4**levels
    surface_vertices = triangles // 2 + 1  # a triangulated patch has about half as many vertices
    return 3 * triangles * n_layers, surface_vertices * (n_layers + 1)


def memory_bytes(dofs: int, solver: str) -> float:
    """Estimated peak resident memory (bytes) of a solve with ``dofs`` unknowns: the calibration
    point scaled like N^(4/3) for the direct solver (LU fill); :data:`ITERATIVE_BYTES_PER_DOF`
    per DOF for the Krylov solver."""
    if solver == "iterative":
        return BASE_BYTES + ITERATIVE_BYTES_PER_DOF * dofs
    return BASE_BYTES + _CALIBRATION_BYTES * (dofs / _CALIBRATION_DOFS) ** (4.0 / 3.0)


def direct_fits(dofs: int, available_bytes: float | None = None) -> bool:
    """Whether the direct (MUMPS LU) solve of ``dofs`` unknowns fits: its estimate times
    :data:`SAFETY` within the memory available (default: :func:`available_memory_bytes`).

    The inner linear solve of the bordered Newton is an LU factorisation while this holds and a
    Krylov method with algebraic multigrid (a Schur-complement field split for Taylor-Hood) past
    it (``SolverOptions.linear_solver = "auto"``): the LU is exact and, below this size, faster;
    the Krylov path is for meshes whose factor would not fit."""
    available = available_memory_bytes() if available_bytes is None else available_bytes
    return SAFETY * memory_bytes(dofs, "direct") <= available


#: The elements whose Krylov path ``auto`` takes from :data:`ITERATIVE_FROM_DOFS` unknowns (the
#: p-multigrid's). P1 (GAMG alone) keeps the LU wherever it fits: on the fine Hertz mesh of
#: tests/fem_reference/test_fe_convergence.py (P1, 35.9k DOFs) the Krylov path's Newton walked
#: away from the obstacle (the Schur complement of the rigid motions, a near-cancellation of the
#: bulk's terms, took the wrong sign from the inexact inner solves) where the LU converges in 15
#: steps (measured 2026-11-28; docs/method.md#the-iterative-path)
ITERATIVE_ELEMENTS = ("P2", "TH")


def iterative_is_default(dofs: int, element: str, available_bytes: float | None = None) -> bool:
    """The ``auto`` choice of the inner linear solve: Krylov from :data:`ITERATIVE_FROM_DOFS`
    unknowns for the elements of :data:`ITERATIVE_ELEMENTS`, or wherever the LU does not fit
    (:func:`direct_fits`)."""
    return (element in ITERATIVE_ELEMENTS and dofs >= ITERATIVE_FROM_DOFS) or not direct_fits(dofs, available_bytes)


def estimate(cells: int, vertices: int, element: str, available_bytes: float | None = None,
             linear_solver: str = "auto") -> FESize:
    """DOFs of the element on a tetrahedral mesh, the solver used and its peak memory.

    Edges of a tetrahedral mesh: about vertices + cells (Euler's formula with two faces per
    cell). P1: 3 per vertex; P2: 3 per vertex and edge; Taylor-Hood: P2 plus 1 per vertex.
    Solver (``linear_solver``, :data:`fem_reference.problem.LINEAR_SOLVERS`): "direct" or
    "iterative" as given; "auto" is :func:`iterative_is_default` (with ``available_bytes``,
    default the memory available now; P1, P2 and Taylor-Hood alike).
    """
    edges = vertices + cells
    dofs = 3 * vertices if element == "P1" else 3 * (vertices + edges) + (vertices if element == "TH" else 0)
    if linear_solver == "auto":
        solver = "iterative" if iterative_is_default(dofs, element, available_bytes) else "direct"
    else:
        solver = linear_solver
    return FESize(cells, vertices, dofs, solver, memory_bytes(dofs, solver))


def available_memory_bytes() -> float:
    """Memory this process may still use: MemAvailable, or the cgroup's limit if lower."""
    available = math.inf
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    available = float(line.split()[1]) * 1024.0
    except OSError:
        pass
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path, encoding="ascii") as f:
                text = f.read().strip()
            with open(path.replace("max", "current").replace("limit_in_bytes", "usage_in_bytes"), encoding="ascii") as f:
                used = float(f.read().strip())
        except (OSError, ValueError):
            continue
        if text.isdigit():
            available = min(available, float(text) - used)
    if not math.isfinite(available):
        pages = os.sysconf("SC_AVPHYS_PAGES") if hasattr(os, "sysconf") else 0
        available = float(pages) * os.sysconf("SC_PAGE_SIZE") if pages else math.inf
    return available


def reset_peak_memory() -> None:
    """Reset this process's peak resident set (Linux: ``/proc/self/clear_refs``, value 5), so that
    :func:`peak_memory_bytes` measures what follows and not an earlier run in the same worker."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
    except OSError:
        pass


def peak_memory_bytes() -> float | None:
    """Peak resident set of this process since the last :func:`reset_peak_memory` (``VmHWM`` of
    ``/proc/self/status``), bytes; None where the kernel does not tell."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return None


def check_fits(size: FESize, mesh_size_mm: float, size_at: Callable[[float], FESize], *, file: str | None, key: str,
               available_bytes: float | None = None) -> None:
    """Refuse (InputError, exit 2) a solve whose memory estimate times :data:`SAFETY` exceeds
    what is available, naming the mesh size, the estimate, the available memory and a mesh size
    that fits: the finest whose estimate ``size_at(mesh_size_mm)`` (the mesher's discrete rules,
    :func:`solid_size`) does (:func:`fitting_size`)."""
    available = available_memory_bytes() if available_bytes is None else available_bytes
    need = SAFETY * size.memory_bytes
    if need > available:
        raise InputError(
            f"mesh size {mesh_size_mm:g} mm gives about {size.cells:,} cells and {size.dofs:,} DOFs; the "
            f"{size.solver} solve needs an estimated {size.memory_bytes / 1e9:.3g} GB ({need / 1e9:.3g} GB with "
            f"a x{SAFETY:g} margin) but {available / 1e9:.3g} GB are available",
            file=file,
            key=key,
            expected=f"a mesh size whose estimate fits (e.g. {_three_digits_up(fitting_size(size_at, mesh_size_mm, available)):g} mm or larger)"
                     + (", or the Krylov solver (linear_solver auto or iterative)" if size.solver == "direct" else ""),
        )


def _three_digits_up(value: float) -> float:
    """``value`` rounded up to three significant digits (a suggested size rounded down could fall
    back below the mesher's threshold)."""
    quantum = 10.0 ** (math.floor(math.log10(value)) - 2)
    return math.ceil(value / quantum - 1e-9) * quantum


#: the steps of :func:`fitting_size`'s search (ratio between candidate mesh sizes, and how many)
_FIT_STEP, _FIT_STEPS = 1.02, 400


def fitting_size(size_at: Callable[[float], FESize], mesh_size_mm: float, available_bytes: float) -> float:
    """The finest mesh size from ``mesh_size_mm`` up (in steps of 2 %) whose estimate ``size_at``
    fits in ``available_bytes`` with the :data:`SAFETY` margin. The mesher refines in factors of 2
    and sets the layers by ceil(thickness / size), or keeps a given number: a size just above a
    refused one often builds the same mesh (with the layers given, anything short of the next
    halving does). The last candidate when none fits."""
    candidate = float(mesh_size_mm)
    for _ in range(_FIT_STEPS):
        candidate *= _FIT_STEP
        if SAFETY * size_at(candidate).memory_bytes <= available_bytes:
            break
    return candidate


def candidate_surface(lengths_mm: np.ndarray, h_max_mm: float, areas_mm2: np.ndarray) -> np.ndarray:
    """Mask of M's triangles the slab is built on (the rule of :func:`geometries.fe_solids.slab_solid`)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(lengths_mm) & (lengths_mm > 0) & (lengths_mm <= h_max_mm) & (areas_mm2 > 0)
