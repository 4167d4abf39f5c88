"""Array kernels on triangles and 3-vectors, one of each for the whole project: row-wise cross
products and closest points on triangles.

Both are vectorised numpy over rows (points, springs, triangles); the DEM solver (``edem``), the
FE reference's rigid obstacles and the verification's surface projections use these, never a
copy of their own.
"""

from __future__ import annotations

import numpy as np

__all__ = ["closest_points_on_triangles", "cross_rows"]


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of (n, 3) arrays (np.cross is several times slower on small arrays).

    Either argument may also be a single (3,) vector; the shapes broadcast over leading axes.
    """
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def closest_points_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared distance (mm^2, shape (...)) and barycentric weights of a, b, c (shape (..., 3)) of
    the closest point to ``p`` on each triangle (a, b, c).

    Arrays (..., 3) in mm broadcast over leading axes, last axis xyz. If the orthogonal projection of p onto
    the triangle's plane falls inside the triangle it is the closest point; otherwise the
    closest point lies on the boundary, the nearest of the three clamped edge projections.
    Degenerate triangles (zero area) are handled by the edge branch alone.
    """
    e0, e1 = b - a, c - a
    v = p - a
    d00 = np.einsum("...i,...i", e0, e0)
    d01 = np.einsum("...i,...i", e0, e1)
    d11 = np.einsum("...i,...i", e1, e1)
    d20 = np.einsum("...i,...i", v, e0)
    d21 = np.einsum("...i,...i", v, e1)
    denom = d00 * d11 - d01 * d01
    ok = denom > 1e-300 * np.maximum(d00 * d11, 1e-300)
    safe = np.where(ok, denom, 1.0)
    s = (d11 * d20 - d01 * d21) / safe
    t = (d00 * d21 - d01 * d20) / safe
    inside = ok & (s >= 0.0) & (t >= 0.0) & (s + t <= 1.0)
    foot = a + s[..., None] * e0 + t[..., None] * e1
    d2_inside = np.einsum("...i,...i", p - foot, p - foot)

    best_d2 = np.full(d00.shape, np.inf)
    best_w = np.zeros(d00.shape + (3,))
    for start, end, i, j in ((a, b, 0, 1), (b, c, 1, 2), (c, a, 2, 0)):
        edge = end - start
        length2 = np.einsum("...i,...i", edge, edge)
        u = np.einsum("...i,...i", p - start, edge) / np.where(length2 > 0.0, length2, 1.0)
        u = np.clip(np.where(length2 > 0.0, u, 0.0), 0.0, 1.0)
        q = start + u[..., None] * edge
        d2 = np.einsum("...i,...i", p - q, p - q)
        better = d2 < best_d2
        best_d2 = np.where(better, d2, best_d2)
        w = np.zeros(d00.shape + (3,))
        w[..., i] = 1.0 - u
        w[..., j] = u
        best_w = np.where(better[..., None], w, best_w)
    w_inside = np.stack([1.0 - s - t, s, t], axis=-1)
    d2 = np.where(inside, d2_inside, best_d2)
    weights = np.where(inside[..., None], w_inside, best_w)
    return d2, weights


def _vertex_to_surface_mm(points_mm: np.ndarray, vertices_mm: np.ndarray, triangles: np.ndarray) -> tuple[float, int]:
    """Smallest distance from the points (n, 3) to the triangle surface (mm) and the point that has it.

    A point's distance to a triangle is at least its distance to the triangle's centroid minus the
    triangle's largest centroid-to-corner distance r, and at most its distance to the nearest
    vertex d_v. So only the points whose d_v can beat the best d_v by the longest edge, and for
    each only the triangles whose centroid lies within min d_v + max r, are measured exactly.
    """
    from scipy.spatial import cKDTree

    corners = vertices_mm[triangles]
    centroids = corners.mean(axis=1)
    reach = float(np.linalg.norm(corners - centroids[:, None], axis=2).max(initial=0.0))
    longest_edge = float(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(initial=0.0))
    nearest_vertex, _ = cKDTree(vertices_mm).query(points_mm)
    bound = float(nearest_vertex.min())
    candidates = np.flatnonzero(nearest_vertex - longest_edge <= bound)
    near = cKDTree(centroids).query_ball_point(points_mm[candidates], bound + reach)
    point_of = np.repeat(candidates, [len(n) for n in near])
    triangle_of = np.fromiter((t for n in near for t in n), np.int64, count=point_of.size)
    squared, _ = closest_points_on_triangles(points_mm[point_of], *np.moveaxis(corners[triangle_of], 1, 0))
    best = int(np.argmin(squared))
    return float(np.sqrt(squared[best])), int(point_of[best])


def closest_distance_mm(a_vertices_mm: np.ndarray, a_triangles: np.ndarray, b_vertices_mm: np.ndarray,
                        b_triangles: np.ndarray) -> tuple[float, np.ndarray]:
    """Closest distance between two triangle surfaces in the same frame (mm) and a point (3,) of
    one of them where it is reached.

    The smaller of the vertex-to-surface distances both ways: exact where the closest pair is a
    vertex and a triangle, an upper bound by at most the sagitta of an edge where it is two edges.
    Surfaces that cross each other have distance 0 along the crossing, which a vertex's distance
    does not see.
    """
    d_ab, i_ab = _vertex_to_surface_mm(a_vertices_mm, b_vertices_mm, b_triangles)
    d_ba, i_ba = _vertex_to_surface_mm(b_vertices_mm, a_vertices_mm, a_triangles)
    return (d_ab, a_vertices_mm[i_ab]) if d_ab <= d_ba else (d_ba, b_vertices_mm[i_ba])
