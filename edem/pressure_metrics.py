"""The regularised peak pressure (docs/method.md#7-comparison-metrics): one definition, used by
every summary.json, the campaigns' metrics and the reports.

The raw peak (the largest nodal or spring pressure) of a contact whose edge is sharp does not
converge under mesh refinement: the continuum's pressure at a rim or a pit edge can be singular,
and the largest value of a field sampled on a finer mesh grows with it. The regularised peak is
the largest mean of the pressure over a disc of 1 mm^2 (:data:`PEAK_DISC_AREA_MM2`) centred on
the surface: for an integrable singularity it converges as the mesh is refined, on the spring bed
and on the FE surface alike (measured in docs/method.md#7-comparison-metrics).

The pressure of a result is the force per area of M, the surface the springs live on
(:func:`pressure_field_on_mobile`): an FE reference's nodal pressure on its contact face times its
columns' area ratio, on the points of M under them; a discrete run's spring pressures on M.
"""

from __future__ import annotations

import math

import numpy as np

from geometries.triangle_kernels import triangle_areas

#: area (mm^2) of the disc the regularised peak averages the pressure over
PEAK_DISC_AREA_MM2 = 1.0
#: quadrature points per disc radius along a triangle edge: the disc's area is then integrated to
#: a few per cent (~60 points per disc), far below the 10 % bands the metric is judged against
_POINTS_PER_RADIUS = 3.0
#: what summary.json says of its regularised_peak_pressure_mpa
REGULARISED_PEAK_DEFINITION = (
    f"the largest mean of the pressure (force per area of M) over a disc of {PEAK_DISC_AREA_MM2:g} mm^2 of the surface, "
    "centred on a triangle centroid or vertex (edem.pressure_metrics): mesh-independent where the raw peak is not")
#: FE point data of the pressure as force per area of M, and the points of M it stands on
PRESSURE_ON_MOBILE = "pressure_on_mobile_mpa"
MOBILE_POINT = "mobile_point_mm"


def _subdivided(points_mm: np.ndarray, triangles: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids of the n^2 sub-triangles of each triangle (uniform barycentric grid): their
    positions (m, n^2, 3), barycentric weights (n^2, 3) and areas (m, n^2) in mm^2."""
    bary = []
    for i in range(n):
        for j in range(n - i):
            bary.append(((i + 1 / 3) / n, (j + 1 / 3) / n))  # upright sub-triangle
            if i + j < n - 1:
                bary.append(((i + 2 / 3) / n, (j + 2 / 3) / n))  # inverted one
    uv = np.array(bary)
    weights = np.column_stack([1.0 - uv.sum(axis=1), uv[:, 0], uv[:, 1]])
    corners = points_mm[triangles]  # (m, 3, 3)
    positions = np.einsum("qk,mkx->mqx", weights, corners)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area = triangle_areas(a, b, c) / (n * n)
    return positions, weights, np.repeat(area[:, None], len(uv), axis=1)


def disc_mean_pressure_mpa(points_mm: np.ndarray, triangles: np.ndarray, pressure_mpa: np.ndarray, *, at_points: bool,
                           disc_area_mm2: float = PEAK_DISC_AREA_MM2) -> tuple[np.ndarray, np.ndarray]:
    """The mean pressure over the disc of area ``disc_area_mm2`` around candidate centres.

    Parameters
    ----------
    points_mm : (n, 3) float
        Surface points, mm.
    triangles : (m, 3) int
        Triangles.
    pressure_mpa : (n,) or (m,) float
        Nodal pressure (``at_points``, linear on each triangle) or one value per triangle, MPa.
    at_points : bool
        Whether ``pressure_mpa`` is nodal.
    disc_area_mm2 : float
        Area of the disc (radius sqrt(area / pi) in 3D: a ball cut by the surface, a disc where the
        surface is flat over the radius).

    Returns
    -------
    centres_mm : (k, 3) float
        The centroids and vertices of the triangles that carry pressure (others cannot hold the peak).
    mean_mpa : (k,) float
        The area-weighted mean pressure over the part of the surface within the disc of each
        centre (zero pressure outside the contact counts; off the surface's edge nothing does).
    """
    points = np.asarray(points_mm, dtype=np.float64)
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    p = np.asarray(pressure_mpa, dtype=np.float64)
    radius = math.sqrt(disc_area_mm2 / math.pi)
    corners = points[tris]
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    loaded = (p[tris].max(axis=1) if at_points else p) > 0.0
    if not loaded.any():
        return np.zeros((0, 3)), np.zeros(0)
    centroids = corners.mean(axis=1)
    centres = np.concatenate([centroids[loaded], points[np.unique(tris[loaded])]])
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree

    # only triangles that reach within a radius of a centre can meet a disc (zero pressure counts)
    reach = cKDTree(centres).query(centroids, distance_upper_bound=radius + float(edge.max()))[0]
    near = np.flatnonzero(reach <= radius + edge)
    # each triangle split into n^2 sub-triangles, n by its longest edge (grouped by n)
    subdivisions = np.maximum(1, np.ceil(edge[near] * _POINTS_PER_RADIUS / radius)).astype(np.int64)
    q_pos, q_val, q_area = [], [], []
    for n in np.unique(subdivisions):
        group = near[subdivisions == n]
        positions, weights, area = _subdivided(points, tris[group], int(n))
        q_pos.append(positions.reshape(-1, 3))
        q_area.append(area.ravel())
        q_val.append((np.einsum("qk,mk->mq", weights, p[tris[group]]) if at_points else np.repeat(p[group][:, None], weights.shape[0], axis=1)).ravel())
    q_pos, q_val, q_area = np.concatenate(q_pos), np.concatenate(q_val), np.concatenate(q_area)
    pairs = cKDTree(centres).sparse_distance_matrix(cKDTree(q_pos), radius, output_type="coo_matrix")
    inside = coo_matrix((np.ones_like(pairs.data), (pairs.row, pairs.col)), shape=pairs.shape).tocsr()
    total = inside @ q_area
    mean = np.divide(inside @ (q_area * q_val), total, out=np.zeros(len(centres)), where=total > 0)
    return centres, mean


def regularised_peak_pressure_mpa(points_mm: np.ndarray, triangles: np.ndarray, pressure_mpa: np.ndarray, *, at_points: bool,
                                  disc_area_mm2: float = PEAK_DISC_AREA_MM2) -> float:
    """The regularised peak: the largest :func:`disc_mean_pressure_mpa` (0 with no pressure), MPa."""
    _centres, mean = disc_mean_pressure_mpa(points_mm, triangles, pressure_mpa, at_points=at_points, disc_area_mm2=disc_area_mm2)
    return float(mean.max(initial=0.0))


def pressure_field_on_mobile(surface) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """(points, triangles, pressure, at_points) of a pressure map (an edem.resultdir.SurfaceFrame)
    as force per area of M: an FE contact face's ``pressure_on_mobile_mpa`` on the points of M
    under it (``mobile_point_mm``; its own points without them), else its nodal ``pressure_mpa``,
    else the spring (cell) pressures of a discrete run. ValueError when the surface has no pressure."""
    point, cell = surface.point_data, surface.cell_data
    if PRESSURE_ON_MOBILE in point:
        return np.asarray(point.get(MOBILE_POINT, surface.points_mm), float), surface.triangles, point[PRESSURE_ON_MOBILE], True
    if "pressure_mpa" in point:
        return surface.points_mm, surface.triangles, point["pressure_mpa"], True
    if "pressure_mpa" in cell:
        return surface.points_mm, surface.triangles, cell["pressure_mpa"], False
    raise ValueError("the surface has no pressure_mpa array")


def has_pressure(surface) -> bool:
    """Whether a pressure map has a pressure field (:func:`pressure_field_on_mobile` reads it)."""
    return "pressure_mpa" in surface.point_data or "pressure_mpa" in surface.cell_data or PRESSURE_ON_MOBILE in surface.point_data


def surface_regularised_peak_mpa(surface) -> float:
    """:func:`regularised_peak_pressure_mpa` of a pressure map's :func:`pressure_field_on_mobile`."""
    points, triangles, pressure, at_points = pressure_field_on_mobile(surface)
    return regularised_peak_pressure_mpa(points, triangles, pressure, at_points=at_points)
