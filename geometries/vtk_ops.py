"""Surface operations done by VTK (the `vtk` extra, imported only inside these functions):
subdividing a surface to a spring spacing (docs/method.md#9-geometry-pre-flight-and-spring-resolution)."""

from __future__ import annotations

import numpy as np

from geometries.errors import InputError
from geometries.extras import import_extra
from geometries.surface import TriangleSurface

#: Largest number of triangles a resampled spring-bearing surface may have (one spring each).
MAX_RESAMPLED_TRIANGLES = 2_000_000


def _vtk(what: str):
    """The vtk modules used here, or MissingExtra naming what needs them and the extra to install."""
    import_extra("vtkmodules", what)
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    return numpy_support, vtkPoints, vtkCellArray, vtkPolyData


def _polydata(vertices_mm: np.ndarray, triangles: np.ndarray, what: str):
    numpy_support, vtkPoints, vtkCellArray, vtkPolyData = _vtk(what)
    points = vtkPoints()
    points.SetData(numpy_support.numpy_to_vtk(np.ascontiguousarray(vertices_mm, dtype=np.float64), deep=True))
    cells = vtkCellArray()
    offsets = np.arange(0, 3 * len(triangles) + 1, 3, dtype=np.int64)
    cells.SetData(numpy_support.numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_support.numpy_to_vtkIdTypeArray(np.ascontiguousarray(triangles, dtype=np.int64).ravel(), deep=True))
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(cells)
    return poly


def subdivide_to_spacing(surface: TriangleSurface, spacing_mm: float, *, key: str | None = None) -> TriangleSurface:
    """The surface with every triangle edge at most ``spacing_mm`` long (VTK's
    vtkAdaptiveSubdivisionFilter: edges longer than the spacing are split at their midpoints).

    New vertices lie on the old edges, so the surface keeps its shape (its facets, its area and
    its area centroid) and its orientation; only the springs, one per triangle, become finer.

    Parameters
    ----------
    surface : TriangleSurface
        (n, 3) vertices in mm, (m, 3) triangles.
    spacing_mm : float
        Longest edge allowed (mm, > 0).
    key : str, optional
        The scene key named by errors.

    Returns
    -------
    TriangleSurface
        The same name and source, more triangles.

    Raises
    ------
    InputError
        When the spacing would give more than :data:`MAX_RESAMPLED_TRIANGLES` triangles, or VTK
        is missing.
    """
    what = f"resampling the spring-bearing surface ({key or 'spring_spacing_mm'})"
    poly = _polydata(surface.vertices_mm, surface.triangles, what)
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersModeling import vtkAdaptiveSubdivisionFilter

    subdivide = vtkAdaptiveSubdivisionFilter()
    subdivide.SetInputData(poly)
    subdivide.SetMaximumEdgeLength(float(spacing_mm))
    subdivide.SetMaximumTriangleArea(np.finfo(np.float64).max)  # (its default, 1, would also split by area)
    subdivide.SetMaximumNumberOfTriangles(MAX_RESAMPLED_TRIANGLES)
    subdivide.SetMaximumNumberOfPasses(1000)  # each pass halves the longest edges: never the limit
    subdivide.Update()
    out = subdivide.GetOutput()
    vertices = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    triangles = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).astype(np.int64).reshape(-1, 3)
    edges = np.linalg.norm(vertices[triangles] - vertices[np.roll(triangles, 1, axis=1)], axis=2)
    if edges.max(initial=0.0) > spacing_mm * (1.0 + 1e-9):
        raise InputError(
            f"spring_spacing_mm = {spacing_mm:g} mm would give more than {MAX_RESAMPLED_TRIANGLES:,} springs on "
            f"the {surface.areas_mm2.sum():.4g} mm^2 spring-bearing surface",
            file=surface.source or None, key=key, expected="a larger spacing (about the expected contact patch's radius / 5)",
        )
    return TriangleSurface(vertices, triangles, name=surface.name, source=surface.source)
