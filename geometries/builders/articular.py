"""Articular cartilage on the built-in ankles (docs/method.md#8-built-in-geometries): the layer's
thickness with its tapered margin, the placement of the tibia so that the two articular surfaces
touch, and the pieces both ankle builders mesh their bones and cartilage with.

Each body is a subchondral bone surface and an articular surface on top of it. Both are meshed
from one planar parameter domain, (x, u) on the talus and (x, s) on the plafond (arc lengths,
+ anterior): the bone is the parametric surface, the articular surface the same vertices moved
by the local thickness t, so the two share their triangles. On the talus t is taken along the
bone's outward normal, so that where t is the centre value the layer is t thick along the normal,
as the scene measures it (docs/method.md#measured-cartilage-thickness); the talar bone curves
gently (radii of curvature above 4 mm against layers below 1.7 mm), so its offset never folds.
On the plafond t is taken along the radius, towards the plafond's axis: the subject-like
plafond's depressions have shoulders curved more tightly than the layer is thick (radius 0.4-0.8
mm), over which an offset along the normal folds; along the radius the layer stays a graph, and
measured along the normal it is t on the idealised plafond and the ridge's crest, within 2 % of t
on the ridge's flanks and 0.76-1.11 t on the default subject's depression shoulders.
The thickness is the centre value times a taper of each margin (:func:`layer_thickness_mm`),
which reaches zero on the articular margin with a zero slope: the articular surface meets its
bone tangentially, and no rim is a step.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from geometries.builders.gmsh_session import mesh_planar_domain, orient_like
from geometries.surface import TriangleSurface

#: default width of each layer's tapered margin (mm): the thickness rises from 0 at the articular
#: margin to its centre value over this distance
DEFAULT_TAPER_MM = 3.0
#: default centre (plateau) thickness of the talar and tibial layers (mm): with the default 3 mm
#: taper their area-weighted means on the ideal ankle come out at 1.09 mm (talus) and 1.14 mm (the
#: plafond), the published means (docs/references.md, Millington et al. 2007: talar 1.10 +- 0.18 mm,
#: tibial 1.16 +- 0.14 mm), and their sum, 2.7 mm, is within a standard deviation of the ankle's
#: radiographic joint space (Goker et al. 2009: 2.44-2.56 +- 0.5 mm)
DEFAULT_TALAR_MM = 1.3
DEFAULT_TIBIAL_MM = 1.4
#: how far below the tibial mesh the nearest talar spring origin is placed (mm): touching, and no
#: spring starts compressed
TOUCH_CLEARANCE_MM = 1e-4
#: step of the central differences that give the bone's normals (mm of the parameters)
_NORMAL_STEP_MM = 1e-5

ParametricMap = Callable[[np.ndarray], np.ndarray]


def edge_taper(distance_mm: np.ndarray, width_mm: float) -> np.ndarray:
    """sin^2 ramp: 0 on the margin (distance 0), 1 from ``width_mm`` inside it; its slope
    vanishes at both ends (C1), so the layer joins its bone and its plateau without a kink."""
    u = np.clip(np.asarray(distance_mm, float) / width_mm, 0.0, 1.0)
    return np.sin(0.5 * math.pi * u) ** 2


def layer_thickness_mm(centre_mm: float, taper_mm: float, ml_distance_mm: np.ndarray, ap_distance_mm: np.ndarray) -> np.ndarray:
    """The layer's thickness (mm) at points ``ml_distance_mm`` inside its medial or lateral margin
    and ``ap_distance_mm`` inside its anterior or posterior one: the centre value times the taper
    of each (0 on the margin, ``centre_mm`` from ``taper_mm`` inside both)."""
    return centre_mm * edge_taper(ml_distance_mm, taper_mm) * edge_taper(ap_distance_mm, taper_mm)


def split_bare_triangles(params: np.ndarray, triangles: np.ndarray, bare: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split each ``bare`` triangle (its three corners on the margin, where the layer is 0) in
    three at its centroid, so that every triangle carries some cartilage: an articular triangle
    on its bone is a layer of thickness 0, which no spring can take.

    ``params`` (n, 2) the parameter-domain vertices, ``triangles`` (m, 3) oriented, ``bare`` (m,)
    bool. Returns the vertices with the centroids appended, the triangles (the bare ones
    replaced by their three, same orientation) and each triangle's parent index."""
    index = np.flatnonzero(bare)
    if index.size == 0:
        return params, triangles, np.arange(len(triangles))
    new = len(params) + np.arange(index.size)
    a, b, c = triangles[index].T
    added = np.vstack([np.column_stack([a, b, new]), np.column_stack([b, c, new]), np.column_stack([c, a, new])])
    kept = np.flatnonzero(~bare)
    parent = np.concatenate([kept, np.tile(index, 3)])
    return np.vstack([params, params[triangles[index]].mean(axis=1)]), np.vstack([triangles[kept], added]), parent


def offset_along_normal(surface: ParametricMap, params: np.ndarray, thickness_mm: np.ndarray, toward: np.ndarray) -> np.ndarray:
    """Points of the parametric ``surface`` (parameters (k, 2) -> (k, 3)) moved by ``thickness_mm``
    (k,) along its unit normal (central differences), the normal's sign the one facing ``toward``
    (k, 3)."""
    h = _NORMAL_STEP_MM
    dx = surface(params + [h, 0.0]) - surface(params - [h, 0.0])
    ds = surface(params + [0.0, h]) - surface(params - [0.0, h])
    normal = np.cross(dx, ds)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    normal *= np.sign(np.einsum("ij,ij->i", normal, toward))[:, None]
    return surface(params) + thickness_mm[:, None] * normal


def vertical_gaps_mm(points_mm: np.ndarray, vertices_mm: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Height (mm) of the triangulated surface (vertices, triangles) above each point (k, 3), along
    +z; NaN where no triangle lies over the point. The surface must be a graph over the x-y
    plane (the plafond is). Each point is located among the triangles whose centroids are
    nearest it in x-y (k-d tree), by its barycentric coordinates."""
    from scipy.spatial import cKDTree

    corners = vertices_mm[triangles]  # (m, 3, 3)
    near = min(24, len(triangles))
    _d, index = cKDTree(corners[:, :, :2].mean(axis=1)).query(points_mm[:, :2], k=near)
    index = index.reshape(len(points_mm), near)
    a, b, c = (corners[index, i] for i in range(3))  # (k, near, 3)
    e1, e2, q = b - a, c - a, points_mm[:, None, :] - a
    det = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        v = (q[..., 0] * e2[..., 1] - q[..., 1] * e2[..., 0]) / det
        w = (e1[..., 0] * q[..., 1] - e1[..., 1] * q[..., 0]) / det
    inside = (v >= -1e-12) & (w >= -1e-12) & (v + w <= 1.0 + 1e-12) & (np.abs(det) > 0)
    z = a[..., 2] + v * e1[..., 2] + w * e2[..., 2]
    height = z[np.arange(len(points_mm)), np.argmax(inside, axis=1)]
    return np.where(inside.any(axis=1), height - points_mm[:, 2], np.nan)


def _cylinder_points(x: np.ndarray, angle: np.ndarray, radius: np.ndarray, axis_z_mm: float) -> np.ndarray:
    """Points at ``radius`` from the axis along x through (0, 0, ``axis_z_mm``), at ``angle`` from +z (+ anterior)."""
    return np.column_stack([x, radius * np.sin(angle), axis_z_mm + radius * np.cos(angle)])


def talus_with_cartilage(params: np.ndarray, triangles: np.ndarray, radius_mm: float, bone_radius: Callable[[np.ndarray, np.ndarray], np.ndarray],
                         thickness: Callable[[np.ndarray, np.ndarray], np.ndarray], name: str) -> tuple[TriangleSurface, TriangleSurface]:
    """The talar articular surface (M) and bone from a mesh of the parameter domain (x, u).

    ``params`` (n, 2) and ``triangles`` (m, 3) mesh the domain (u: arc length on the cylinder of
    ``radius_mm`` about the talar axis, x through (0, 0, -R)); ``bone_radius(x, u)`` is the bone's
    distance from the axis, ``thickness(x, u)`` the layer's along the bone's outward normal (0 on
    the margin). Both surfaces share the triangles, their normals out of the talus.
    """
    params, triangles, _ = split_bare_triangles(params, triangles, (thickness(params[:, 0], params[:, 1]) == 0.0)[triangles].all(axis=1))

    def bone(q: np.ndarray) -> np.ndarray:
        return _cylinder_points(q[:, 0], q[:, 1] / radius_mm, bone_radius(q[:, 0], q[:, 1]), -radius_mm)

    bone_v = bone(params)
    radial = bone_v - np.array([0.0, 0.0, -radius_mm])
    radial[:, 0] = 0.0
    articular_v = offset_along_normal(bone, params, thickness(params[:, 0], params[:, 1]), radial)
    triangles = orient_like(articular_v, triangles, radial[triangles].mean(axis=1), f"{name} talus")
    orient_like(bone_v, triangles, radial[triangles].mean(axis=1), f"{name} talar bone")  # the same triangles face out of the bone too
    return (TriangleSurface(articular_v, triangles, name=f"{name} talus, articular surface", source=name),
            TriangleSurface(bone_v, triangles.copy(), name=f"{name} talus, subchondral bone", source=name))


def tibia_with_cartilage(
    name: str,
    medial_x_mm: float,
    lateral_x_mm: float,
    half_length_mm: float,
    wall_depth_mm: float,
    angle_radius_mm: float,
    axis_z_mm: float,
    bone_radius: Callable[[np.ndarray, np.ndarray], np.ndarray],
    thickness: Callable[[np.ndarray, np.ndarray], np.ndarray],
    wall_thickness_mm: float,
    tilt: np.ndarray,
    pivot_mm: np.ndarray,
    talus: TriangleSurface,
    mesh_size_mm: float,
) -> tuple[TriangleSurface, TriangleSurface, float, np.ndarray]:
    """The tibial plafond and medial malleolus, bone and articular surfaces, placed touching the talus.

    The plafond is the domain [``medial_x_mm``, ``lateral_x_mm``] x [-L/2, L/2] of (x, s), s the
    arc length (angle s / ``angle_radius_mm`` from +z about the plafond's axis along x through
    (0, 0, ``axis_z_mm``)); its bone lies ``bone_radius(x, s)`` from that axis and its articular
    surface ``thickness(x, s)`` nearer the axis (towards the talus). The malleolus
    is a vertical wall x = ``medial_x_mm`` facing laterally, ``wall_depth_mm`` down from the
    plafond's medial edge (meshed with the plafond, its domain unfolded beside it; none for a
    depth of 0), with a uniform layer ``wall_thickness_mm`` (its bone the wall moved medially: a
    component of its own). The tibia is turned by ``tilt`` about ``pivot_mm``, then moved along z
    until the centroids of ``talus`` (the talar articular mesh: the springs' origins) lie at least
    :data:`TOUCH_CLEARANCE_MM` below its articular mesh, one of them exactly so
    (:func:`vertical_gaps_mm`): the articular surfaces touch there and no spring starts compressed.

    Returns the articular surface (F, normals towards the talus), the bone (normals towards the
    articular surface), the lift (mm, from the plafond's given axis) and the touching point (the
    talar centroid that touches, mm).
    """
    S = half_length_mm
    plafond = [(medial_x_mm, -S), (lateral_x_mm, -S), (lateral_x_mm, S), (medial_x_mm, S)]
    wall = [(medial_x_mm - wall_depth_mm, -S), (medial_x_mm, -S), (medial_x_mm, S), (medial_x_mm - wall_depth_mm, S)]
    params, triangles, region = mesh_planar_domain(f"{name}_tibia", [plafond, wall] if wall_depth_mm > 0 else [plafond], mesh_size_mm)
    on_plafond = region == 0
    bare = on_plafond & (thickness(np.maximum(params[:, 0], medial_x_mm), params[:, 1]) == 0.0)[triangles].all(axis=1)
    params, triangles, parent = split_bare_triangles(params, triangles, bare)
    on_plafond = on_plafond[parent]
    xe = np.maximum(params[:, 0], medial_x_mm)  # the wall's points: the plafond's medial edge ...
    below = np.maximum(medial_x_mm - params[:, 0], 0.0)  # ... lowered by how far the unfolded domain lies beside it

    def bone(q: np.ndarray) -> np.ndarray:
        return _cylinder_points(q[:, 0], q[:, 1] / angle_radius_mm, bone_radius(q[:, 0], q[:, 1]), axis_z_mm)

    edge = np.column_stack([xe, params[:, 1]])
    bone_top = bone(edge)
    towards_axis = np.array([0.0, 0.0, axis_z_mm]) - bone_top
    towards_axis[:, 0] = 0.0
    articular_top = bone_top + thickness(xe, params[:, 1])[:, None] * towards_axis / np.linalg.norm(towards_axis, axis=1)[:, None]
    down = np.column_stack([np.zeros_like(below), np.zeros_like(below), -below])
    # in the tibia's own frame: the plafond's articular surface, the wall from its medial edge down
    articular_v = articular_top + down
    plafond_bone_v = bone_top + down
    wall_bone_v = articular_v - [wall_thickness_mm, 0.0, 0.0]
    expected = towards_axis[triangles].mean(axis=1)
    expected[~on_plafond] = np.array([1.0, 0.0, 0.0])  # the wall faces laterally
    # the bone: the plafond's triangles on the plafond's bone, the wall's on the wall's (another component)
    bone_triangles = np.where(on_plafond[:, None], triangles, triangles + len(params))
    used, compact = np.unique(bone_triangles, return_inverse=True)
    bone_v, bone_triangles = np.vstack([plafond_bone_v, wall_bone_v])[used], compact.reshape(bone_triangles.shape)

    def placed(v: np.ndarray) -> np.ndarray:
        return (v - pivot_mm) @ tilt.T + pivot_mm

    articular_v, bone_v, expected = placed(articular_v), placed(bone_v), expected @ tilt.T
    triangles = orient_like(articular_v, triangles, expected, f"{name} tibia")
    bone_triangles = orient_like(bone_v, bone_triangles, expected, f"{name} tibial bone")  # facing the articular surface, as it does
    gaps = vertical_gaps_mm(talus.centroids_mm, articular_v, triangles[on_plafond])
    if not np.isfinite(gaps).any():
        raise RuntimeError(f"{name}: the plafond lies over no part of the talus")
    nearest = int(np.nanargmin(gaps))
    lift = TOUCH_CLEARANCE_MM - float(gaps[nearest])
    up = np.array([0.0, 0.0, lift])
    return (TriangleSurface(articular_v + up, triangles, name=f"{name} tibia, articular surface (plafond + medial malleolus)", source=name),
            TriangleSurface(bone_v + up, bone_triangles, name=f"{name} tibia, subchondral bone", source=name), lift,
            talus.centroids_mm[nearest].copy())
