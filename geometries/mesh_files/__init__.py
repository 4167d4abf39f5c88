"""Mesh files, both ways: :func:`read_surface` and :func:`write_surface` pick the module that owns
the format by its extension (docs/method.md#8-built-in-geometries).

* :mod:`.meshio_family`: STL (ascii or binary), OBJ and PLY, through meshio;
* :mod:`.vtk_family`: legacy VTK, VTP and VTU, through VTK (and meshio for writing .vtk/.vtu).

Reading keeps triangles, converts metres to mm and checks what every later step trusts (indices
in range, finite coordinates within a kilometre) before VTK triangulates polygons. Every
bad-input error is an :class:`~geometries.errors.InputError` naming the file, the scene key,
what is wrong and what was expected. Cleaning and orientation are :mod:`geometries.repair`.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import numpy as np

from geometries.errors import InputError
from geometries.mesh_files import meshio_family, vtk_family
from geometries.mesh_files.common import MAX_COORDINATE_MM, SUPPORTED_FORMATS, Cells, fmt_point
from geometries.mesh_files.vtk_family import vtp_text, write_vtp
from geometries.surface import TriangleSurface

__all__ = ["MAX_COORDINATE_MM", "SUPPORTED_FORMATS", "read_surface", "vtp_text", "write_surface", "write_vtp"]

#: the module that reads and writes each format, by extension
FAMILIES: dict[str, ModuleType] = {suffix: family for family in (meshio_family, vtk_family) for suffix in family.FORMATS}


def _family(path: Path, key: str | None, what: str = "file (by extension)") -> ModuleType:
    family = FAMILIES.get(path.suffix.lower())
    if family is None:
        raise InputError(f"unknown mesh format '{path.suffix}'", file=str(path), key=key,
                         expected=f"a {SUPPORTED_FORMATS} {what}")
    return family


def _triangles(points: np.ndarray, polys: list[Cells], strips: list[Cells]) -> np.ndarray:
    """(m, 3) triangles of the cells: triangles as they are, anything else through VTK's
    triangulation (:func:`.vtk_family.triangulate`, which passes triangles unchanged)."""
    if not strips and all(np.all(sizes == 3) for sizes, _ in polys):
        return np.concatenate([c for _, c in polys]).reshape(-1, 3)
    return vtk_family.triangulate(points, polys, strips)


def read_surface(
    path: str | Path, *, units: str = "mm", key: str | None = None, name: str = ""
) -> TriangleSurface:
    """Read the triangles of a surface mesh file, in mm, without cleaning (docs/method.md#8-built-in-geometries).

    Formats: STL (ascii/binary), OBJ and PLY through meshio; legacy VTK (any dataset type, e.g.
    POLYDATA or UNSTRUCTURED_GRID), VTP and VTU through VTK's own readers. Triangles are kept,
    quads and polygons are triangulated and triangle strips unrolled (vtkTriangleFilter),
    higher-order triangles/quads keep their corner nodes (warning); other 2D cells are dropped
    with a warning; 0D, 1D and 3D cells are ignored. ``units`` is "mm" (default) or "m"
    (coordinates multiplied by 1000).

    Raises InputError (naming ``path`` and the scene ``key``) for a missing file, an unknown or
    unreadable format, a file without triangles, indices out of range and NaN/inf coordinates.
    """
    path = Path(path)
    file = str(path)
    if units not in ("mm", "m"):
        raise InputError(f"unknown length unit '{units}'", file=file, key=key,
                         expected='units = "mm" or "m"')
    try:
        exists, is_file = path.exists(), path.is_file()
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise InputError(f"cannot open the mesh file: {exc.strerror}", file=file, key=key,
                         expected="a path the file system accepts") from None
    if not exists:
        raise InputError("mesh file not found", file=file, key=key,
                         expected=f"an existing {SUPPORTED_FORMATS} file (paths are relative "
                         "to the scene file)")
    if not is_file:
        raise InputError("mesh path is not a file", file=file, key=key,
                         expected=f"a {SUPPORTED_FORMATS} file")

    points, polys, strips, types = _family(path, key).read(path, key)

    indices = np.concatenate([c for _, c in polys + strips] + [np.empty(0, dtype=np.int64)])
    tri = np.empty((0, 3), dtype=np.int64)
    if len(indices):  # checked before VTK triangulates: it trusts indices and coordinates
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"points have shape {points.shape}", file=file, key=key,
                             expected="3D point coordinates")
        if indices.min() < 0 or indices.max() >= len(points):
            raise InputError(f"cell vertex indices out of range (0..{len(points) - 1})",
                             file=file, key=key, expected="indices of existing points")
        bad = ~np.isfinite(points).all(axis=1)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise InputError(f"{int(bad.sum())} vertices have NaN or infinite coordinates "
                             f"(first: vertex {first})", file=file, key=key,
                             expected="finite coordinates")
        # No joint is larger than a kilometre; beyond that, squared distances (KD-trees, areas)
        # and Embree's float32 coordinates overflow or lose every digit.
        huge = np.abs(points).max(axis=1) * (1000.0 if units == "m" else 1.0) > MAX_COORDINATE_MM
        if huge.any():
            first = int(np.flatnonzero(huge)[0])
            raise InputError(f"{int(huge.sum())} vertices lie farther than {MAX_COORDINATE_MM:g} mm from "
                             f"the origin (first: vertex {first}, {fmt_point(points[first])})", file=file,
                             key=key, expected=f"coordinates in {units} within +-{MAX_COORDINATE_MM:g} mm")
        tri = _triangles(points, polys, strips)
    if len(tri) == 0:
        found = ", ".join(sorted(set(types))) or "none"
        raise InputError(f"the mesh has no triangles (cell types found: {found})", file=file,
                         key=key, expected="a triangulated surface mesh (extract the bone "
                         "surface first if this is a volume mesh)")
    scale = 1000.0 if units == "m" else 1.0
    return TriangleSurface(
        vertices_mm=np.ascontiguousarray(points * scale, dtype=np.float64),
        triangles=np.ascontiguousarray(tri, dtype=np.int64),
        name=name or path.stem,
        source=file,
    )


def write_surface(
    path: str | Path, surface: TriangleSurface, *, binary: bool | None = None
) -> None:
    """Write the surface's triangles to ``path``; the format follows the extension (docs/method.md#8-built-in-geometries).

    VTP through :func:`write_vtp` (VTK, binary float64); STL, OBJ, PLY, VTK and VTU through
    ``meshio.write``. ``binary=None`` picks the lossless variant: ascii STL (binary STL stores
    float32), binary PLY/VTK/VTU (float64). OBJ is always ascii (full float repr).
    """
    path = Path(path)
    _family(path, None, "file name").write(path, surface, binary)
