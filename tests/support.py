"""Small exact geometries and scene builders shared by the tests (numpy, and scipy for a Delaunay disk)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from edem.scene import Scene
from edem.thin_layer import SurfaceMesh
from geometries.surface import TriangleSurface


def grid_plate(width_mm: float, depth_mm: float, n: int, z_mm: float = 0.0, facing_up: bool = True) -> TriangleSurface:
    """A square-gridded plate centred on the z axis, triangle normals +z (or -z)."""
    x = np.linspace(-width_mm / 2, width_mm / 2, n + 1)
    y = np.linspace(-depth_mm / 2, depth_mm / 2, n + 1)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    vertices = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z_mm)])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    if not facing_up:
        tris = tris[:, ::-1]
    return TriangleSurface(vertices, tris)


def plane(z_of_xy, size_mm: float = 200.0) -> TriangleSurface:
    """Two large triangles of the plane z = z_of_xy(x, y) (affine), facing down (-z)."""
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * size_mm
    vertices = np.column_stack([corners, [z_of_xy(x, y) for x, y in corners]])
    return TriangleSurface(vertices, np.array([[0, 2, 1], [0, 3, 2]]))


def paraboloid(radius_mm: float, apex_mm, half_width_mm: float, n: int) -> TriangleSurface:
    """z = apex_z + ((x - x0)^2 + (y - y0)^2) / (2 R) on an n x n grid around the apex (a vertex),
    triangles facing down (-z)."""
    x0, y0, z0 = apex_mm
    u = np.linspace(-half_width_mm, half_width_mm, n + 1)
    xx, yy = np.meshgrid(u + x0, u + y0, indexing="ij")
    z = z0 + ((xx - x0) ** 2 + (yy - y0) ** 2) / (2.0 * radius_mm)
    idx = np.arange(xx.size).reshape(xx.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return TriangleSurface(np.column_stack([xx.ravel(), yy.ravel(), z.ravel()]), np.vstack([np.column_stack([a, c, b]), np.column_stack([a, d, c])]))


def cylinder_patch(radius_mm: float, width_mm: float, arc_deg: float, n_arc: int, n_width: int) -> TriangleSurface:
    """Cylinder patch, axis along x through (0, 0, -R), arc centred on the top (z = 0); normals outward."""
    theta = np.radians(np.linspace(-arc_deg / 2, arc_deg / 2, n_arc + 1))
    x = np.linspace(-width_mm / 2, width_mm / 2, n_width + 1)
    xx, tt = np.meshgrid(x, theta, indexing="ij")
    vertices = np.column_stack([xx.ravel(), radius_mm * np.sin(tt.ravel()), radius_mm * np.cos(tt.ravel()) - radius_mm])
    idx = np.arange(xx.size).reshape(xx.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    surface = TriangleSurface(vertices, tris)
    # Outward = away from the axis: flip if the first triangle points inward.
    axis_to_c = surface.centroids_mm[0] - np.array([surface.centroids_mm[0, 0], 0.0, -radius_mm])
    if surface.unit_normals[0] @ axis_to_c < 0:
        surface = TriangleSurface(vertices, tris[:, ::-1])
    return surface


def make_scene(
    mobile: TriangleSurface,
    fixed: TriangleSurface,
    force_n,
    *,
    youngs_modulus_mpa: float = 10.35,
    poissons_ratio: float = 0.42,
    max_spring_length_mm: float = 3.5,
    **options,
) -> Scene:
    """Scene.from_arrays with the tests' cartilage (E 10.35 MPa, nu 0.42, h_max 3.5 mm)."""
    return Scene.from_arrays(
        mobile.vertices_mm, mobile.triangles, fixed.vertices_mm, fixed.triangles, force_n,
        youngs_modulus_mpa=youngs_modulus_mpa, poissons_ratio=poissons_ratio, max_spring_length_mm=max_spring_length_mm,
        name="test", **options,
    )


def periodic_grid(n: int, spacing_mm: float, n_y: int | None = None) -> tuple[SurfaceMesh, np.ndarray]:
    """Flat n x n (or n x n_y) square grid, two right triangles per square, periodic both ways (a
    flat torus; n_y = 3 squares across is a plane-strain strip for loads uniform along y).

    Returns the mesh and the triangle centroids (unwrapped, mm). Square (i, j): L = (v00, v10, v11),
    U = (v00, v11, v01); L triangles come first.
    """
    n_y = n if n_y is None else n_y
    i, j = np.meshgrid(np.arange(n), np.arange(n_y), indexing="ij")
    i, j = i.ravel(), j.ravel()
    vid = lambda a, b: (a % n) * n_y + (b % n_y)  # noqa: E731
    xy = lambda a, b: np.column_stack([a * spacing_mm, b * spacing_mm, np.zeros(a.shape)])  # noqa: E731
    lower = (np.column_stack([vid(i, j), vid(i + 1, j), vid(i + 1, j + 1)]), np.stack([xy(i, j), xy(i + 1, j), xy(i + 1, j + 1)], axis=1))
    upper = (np.column_stack([vid(i, j), vid(i + 1, j + 1), vid(i, j + 1)]), np.stack([xy(i, j), xy(i + 1, j + 1), xy(i, j + 1)], axis=1))
    tri = np.vstack([lower[0], upper[0]])
    corners = np.concatenate([lower[1], upper[1]])
    return SurfaceMesh.from_corners(tri, corners), corners.mean(axis=1)


def disk_plate(radius_mm: float, n_rings: int) -> TriangleSurface:
    """A flat disk facing up (+z), Delaunay-triangulated rings of 6k points (k = 0 .. n_rings)."""
    points = [np.zeros((1, 2))]
    for k in range(1, n_rings + 1):
        angle = np.linspace(0.0, 2 * np.pi, 6 * k, endpoint=False)
        points.append(radius_mm * k / n_rings * np.column_stack([np.cos(angle), np.sin(angle)]))
    xy = np.vstack(points)
    tri = Delaunay(xy).simplices
    u, v = xy[tri[:, 1]] - xy[tri[:, 0]], xy[tri[:, 2]] - xy[tri[:, 0]]
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    tri = np.where((cross > 0)[:, None], tri, tri[:, ::-1])
    return TriangleSurface(np.column_stack([xy, np.zeros(len(xy))]), tri)
