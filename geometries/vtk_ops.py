"""Surface operations done by VTK (imported only inside these functions): subdividing a surface
to a spring spacing, and the closest distance between two surfaces (docs/method.md#9-geometry-pre-flight-and-spring-resolution)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from geometries.errors import InputError
from geometries.surface import TriangleSurface

#: Largest number of triangles a resampled spring-bearing surface may have (one spring each).
MAX_RESAMPLED_TRIANGLES = 2_000_000


def _vtk(what: str):
    """The vtk modules used here, or InputError naming what needs them and how to get them."""
    try:
        from vtkmodules.util import numpy_support
        from vtkmodules.vtkCommonCore import vtkPoints
        from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    except ImportError as exc:
        raise InputError(f"{what} needs VTK, which is not importable ({exc})",
                         expected="the vtk package (pip install vtk, or reinstall edem with its dependencies)") from None
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


def _longest_edge_mm(surface: TriangleSurface) -> float:
    v, t = surface.vertices_mm, surface.triangles
    return float(np.linalg.norm(v[t] - v[np.roll(t, 1, axis=1)], axis=2).max(initial=0.0))


def _vertex_to_surface_mm(points_mm: np.ndarray, surface: TriangleSurface) -> tuple[float, int]:
    """Smallest distance from the points to the surface (mm) and the point that has it.

    A point's distance to the surface is at least its distance to the nearest vertex minus the
    longest edge (every point of a triangle lies within its longest edge of each corner), so only
    the points that can beat the best vertex-to-vertex distance are measured exactly, by VTK's
    vtkImplicitPolyDataDistance (closest point on the triangles).
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkDoubleArray
    from vtkmodules.vtkFiltersCore import vtkImplicitPolyDataDistance

    nearest_vertex, _ = cKDTree(surface.vertices_mm).query(points_mm)
    candidates = np.flatnonzero(nearest_vertex - _longest_edge_mm(surface) <= nearest_vertex.min())
    distance = vtkImplicitPolyDataDistance()
    distance.SetInput(_polydata(surface.vertices_mm, surface.triangles, "the pre-flight's closest distance"))
    values = vtkDoubleArray()
    distance.FunctionValue(numpy_to_vtk(np.ascontiguousarray(points_mm[candidates]), deep=True), values)
    exact = np.abs(vtk_to_numpy(values))
    best = int(np.argmin(exact))
    return float(exact[best]), int(candidates[best])


def closest_distance_mm(a: TriangleSurface, b: TriangleSurface) -> tuple[float, np.ndarray]:
    """Closest distance between two surfaces in the same frame (mm) and a point of ``a`` or
    ``b`` where it is reached (3,).

    The smaller of the vertex-to-surface distances both ways: exact where the closest pair is a
    vertex and a triangle, an upper bound by at most the sagitta of an edge where it is two edges.
    Surfaces that cross each other have distance 0 along the crossing, which this measure (a
    vertex's distance) does not see: the pre-flight reports the springs' signed ray lengths too.
    """
    d_ab, i_ab = _vertex_to_surface_mm(a.vertices_mm, b)
    d_ba, i_ba = _vertex_to_surface_mm(b.vertices_mm, a)
    return (d_ab, a.vertices_mm[i_ab]) if d_ab <= d_ba else (d_ba, b.vertices_mm[i_ba])
