"""Array kernels on triangles and 3-vectors, one of each for the whole project: row-wise cross
products, triangle areas (and area vectors) and closest points on triangles.

Both are vectorised numpy over rows (points, springs, triangles); the DEM solver (``edem``), the
FE reference's rigid obstacles and the verification's surface projections use these, never a
copy of their own.
"""

from __future__ import annotations

import numpy as np

__all__ = ["closest_points_on_triangles", "cross_rows", "nearby_distance_mm", "triangle_area_vectors", "triangle_areas"]


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of (n, 3) arrays (np.cross is several times slower on small arrays).

    Either argument may also be a single (3,) vector; the shapes broadcast over leading axes.
    """
    # (rows by rows, or rows by one vector, need no broadcast_shapes, whose Python costs ~4 us)
    shape = a.shape if a.shape == b.shape or b.shape == (3,) else np.broadcast_shapes(a.shape, b.shape)
    out = np.empty(shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def triangle_area_vectors(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(n, 3) half the cross product of two edges of the triangles with corners ``a``, ``b``, ``c``
    (each (n, 3), mm): area (mm^2) times the unit normal of the right-hand rule."""
    return 0.5 * cross_rows(b - a, c - a)


def triangle_areas(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(n,) areas (mm^2) of the triangles with corners ``a``, ``b``, ``c`` (each (n, 3), mm); 0 for
    a degenerate one."""
    return np.linalg.norm(triangle_area_vectors(a, b, c), axis=1)


def _dot(u: list[np.ndarray], v: list[np.ndarray]) -> np.ndarray:
    """Dot product of two vectors given as their three component arrays (x, y, z)."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def closest_points_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared distance (mm^2, shape (...)) and barycentric weights of a, b, c (shape (..., 3)) of
    the closest point to ``p`` on each triangle (a, b, c).

    Arrays (..., 3) in mm broadcast over leading axes, last axis xyz. If the orthogonal projection of p onto
    the triangle's plane falls inside the triangle it is the closest point; otherwise the
    closest point lies on the boundary, the nearest of the three clamped edge projections.
    Degenerate triangles (zero area) are handled by the edge branch alone.

    The arithmetic runs on the x, y and z components as separate arrays: numpy pays per row on
    a last axis of 3 (products with a broadcast (..., 1) factor, reductions over xyz), which made
    the (..., 3) form 1.5-2x slower on the tens of thousands of point-triangle pairs of a
    pre-flight. The weights are formed once, from the winning edge and its parameter.
    """
    p, a, b, c = ([x[..., i] for i in range(3)] for x in (p, a, b, c))
    e0 = [bi - ai for ai, bi in zip(a, b)]
    e1 = [ci - ai for ai, ci in zip(a, c)]
    v = [pi - ai for ai, pi in zip(a, p)]
    d00, d01, d11, d20, d21 = _dot(e0, e0), _dot(e0, e1), _dot(e1, e1), _dot(v, e0), _dot(v, e1)
    denom = d00 * d11 - d01 * d01
    ok = denom > 1e-300 * np.maximum(d00 * d11, 1e-300)
    safe = np.where(ok, denom, 1.0)
    s = (d11 * d20 - d01 * d21) / safe
    t = (d00 * d21 - d01 * d20) / safe
    inside = ok & (s >= 0.0) & (t >= 0.0) & (s + t <= 1.0)
    off_foot = [pi - (ai + s * e0i + t * e1i) for pi, ai, e0i, e1i in zip(p, a, e0, e1)]  # p - foot
    d2_inside = _dot(off_foot, off_foot)

    shape = d00.shape
    best_d2 = np.full(shape, np.inf)
    best_u = np.zeros(shape)  # parameter along the nearest edge, from its start
    best_edge = np.full(shape, -1)  # 0: a to b, 1: b to c, 2: c to a; -1: none (nan distances)
    for edge_index, (start, end) in enumerate(((a, b), (b, c), (c, a))):
        edge = [ei - si for si, ei in zip(start, end)]
        length2 = _dot(edge, edge)
        from_start = [pi - si for si, pi in zip(start, p)]
        u = _dot(from_start, edge) / np.where(length2 > 0.0, length2, 1.0)
        u = np.clip(np.where(length2 > 0.0, u, 0.0), 0.0, 1.0)
        off_edge = [pi - (si + u * ei) for si, pi, ei in zip(start, p, edge)]  # p - q
        d2 = _dot(off_edge, off_edge)
        better = d2 < best_d2
        best_d2 = np.where(better, d2, best_d2)
        best_u = np.where(better, u, best_u)
        best_edge = np.where(better, edge_index, best_edge)
    # The edge from vertex i to vertex j gives i the weight 1 - u and j the weight u.
    from_end = 1.0 - best_u
    on_edge = (
        np.where(best_edge == 0, from_end, np.where(best_edge == 2, best_u, 0.0)),
        np.where(best_edge == 1, from_end, np.where(best_edge == 0, best_u, 0.0)),
        np.where(best_edge == 2, from_end, np.where(best_edge == 1, best_u, 0.0)),
    )
    weights = np.stack([np.where(inside, w_in, w_edge) for w_in, w_edge in zip((1.0 - s - t, s, t), on_edge)], axis=-1)
    return np.where(inside, d2_inside, best_d2), weights


def nearby_distance_mm(points_mm: np.ndarray, vertices_mm: np.ndarray, triangles: np.ndarray, candidates: int = 12) -> np.ndarray:
    """(n,) distance (mm) from each point (n, 3) to the nearest of the ``candidates`` triangles
    whose centroids lie nearest it: the distance to the surface for a point on or near it (the
    triangle it lies on is among them on any mesh without slivers far longer than their
    neighbours), an upper bound of it otherwise."""
    from scipy.spatial import cKDTree

    points_mm = np.asarray(points_mm, float).reshape(-1, 3)
    if not len(points_mm):
        return np.zeros(0)
    corners = np.asarray(vertices_mm, float)[np.asarray(triangles, np.int64)]
    k = min(int(candidates), len(corners))
    _, near = cKDTree(corners.mean(axis=1)).query(points_mm, k=k)
    near = near.reshape(len(points_mm), k)
    squared, _ = closest_points_on_triangles(points_mm[:, None, :], *(corners[near, i] for i in range(3)))
    return np.sqrt(squared.min(axis=1))


# Point-triangle pairs measured first, those with the smallest lower bound: the best of them
# bounds the distance, and only the pairs whose bound is below that are measured after.
_FIRST_PAIRS = 64
# Every this-many-th point's nearest vertex gives the first bound on the distance.
_SAMPLE_STRIDE = 16


def _vertex_to_surface_mm(points_mm: np.ndarray, vertices_mm: np.ndarray, triangles: np.ndarray) -> tuple[float, int]:
    """Smallest distance from the points (n, 3) to the triangle surface (mm) and the point that has it.

    A point's distance to a triangle is at least its distance to the triangle's centroid minus the
    triangle's largest centroid-to-corner distance r, and the smallest distance is at most any
    point's distance to its nearest vertex d_v (here the least over every 16th point). So only
    the pairs whose centroid lies within that d_v + max r of the point are candidates (a k-d
    tree over all the points against one over the centroids finds them). A pair's distance is
    also at least sqrt(plane^2 + (aside - r)^2), with the point's distance to the triangle's
    plane and its foot's distance from the centroid, aside: the :data:`_FIRST_PAIRS` pairs with
    the smallest bound are measured exactly, and of the others only those whose bound is below
    the best of them (large triangles, e.g. a box of a dozen, give every point several pairs, of
    which few come near; conforming joint surfaces give each point many near planes, of which
    few triangles lie below it).
    """
    from scipy.spatial import cKDTree

    corners = vertices_mm[triangles]
    centroids = corners.mean(axis=1)
    spokes = corners - centroids[:, None]
    spoke = np.sqrt((spokes * spokes).sum(axis=2).max(axis=1, initial=0.0))  # r of every triangle
    reach = float(spoke.max(initial=0.0))
    # The nearest vertex of every _SAMPLE_STRIDE-th point bounds the smallest distance from above
    # (a search from every point costs several times the pairs below, on joint surfaces whose
    # points lie near the other surface over a wide area).
    bound = float(cKDTree(vertices_mm).query(points_mm[::_SAMPLE_STRIDE])[0].min())
    # All (point, triangle) pairs within the radius as two index arrays (no list per point): a
    # pair further apart is further than the bound. The radius is padded by round-off so that
    # a centroid exactly on it is never lost.
    near = cKDTree(points_mm).sparse_distance_matrix(cKDTree(centroids), (bound + reach) * (1.0 + 1e-12), output_type="ndarray")
    point_of, triangle_of = near["i"], near["j"]
    normal = cross_rows(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    size = np.sqrt(np.einsum("ij,ij->i", normal, normal))
    unit = normal / np.where(size > 0.0, size, 1.0)[:, None]  # (degenerate: zero, plane distance 0)
    offset = points_mm[point_of] - corners[triangle_of, 0]
    plane = np.einsum("ij,ij->i", offset, unit[triangle_of])
    plane *= plane
    # A pair's squared distance is at least the plane's squared distance plus that of the point's
    # foot on the plane from the triangle, which lies within r of the centroid:
    # (sqrt(|p - c|^2 - plane^2) - r)^2 where positive (near conforming surfaces, most pairs'
    # planes are near, but their triangles are off to the side).
    aside = np.sqrt(np.maximum(near["v"] * near["v"] - plane, 0.0)) - spoke[triangle_of]
    lower = plane + np.square(np.maximum(aside, 0.0))
    first = np.argpartition(lower, _FIRST_PAIRS)[:_FIRST_PAIRS] if lower.size > _FIRST_PAIRS else np.arange(lower.size)
    squared = closest_points_on_triangles(points_mm[point_of[first]], *np.moveaxis(corners[triangle_of[first]], 1, 0))[0]
    # Pairs whose bound lies within the best distance so far, with a margin far above the
    # round-off of either figure (~1e-15 of the coordinates) and far below any distance that matters.
    within = np.sqrt(squared.min()) + 1e-9 * (bound + reach)
    rest = np.flatnonzero(lower <= within * within)  # (may repeat some of the first: measured twice, alike)
    measured = np.concatenate([first, rest])
    squared = np.concatenate([squared, closest_points_on_triangles(points_mm[point_of[rest]], *np.moveaxis(corners[triangle_of[rest]], 1, 0))[0]])
    best = int(np.argmin(squared))
    return float(np.sqrt(squared[best])), int(point_of[measured[best]])


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
