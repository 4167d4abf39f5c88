"""FE models of a scene's cartilage: one class per model, registered in :data:`FE_MODELS`.

A model builds, for one time point, the solid bonded to the mobile body M (a
:class:`geometries.fe_solids.FESolid`) and says how its contact surface relates to the springs:

* ``slab`` (:class:`SlabModel`, twin of the ``threshold`` law): the conforming slab between M's
  candidate surface and F. The spring lengths are ray-cast exactly as
  :func:`edem.springs.spring_geometry` does (M at its initial pose, F at the time point's pose;
  candidates: a hit with 0 < h <= h_max). The slab's top vertices are then moved onto F along
  their extrusion direction (a ray cast from the bottom vertex), so the slab touches F exactly
  where it can: the initial gap is zero to round-off. It depends on F's pose.
* ``layer`` (:class:`LayerModel`, twin of the ``gap`` laws): a uniform layer of
  ``cartilage.thickness_mm`` bonded to M; the initial gap to F comes from the geometry. One
  mesh for every pose.
* ``two-layer`` (:class:`TwoLayerModel`, twin of the ``gap`` laws with cartilage on both bones):
  M's layer as ``layer`` builds it and F's own, both elastic, in frictionless contact
  (docs/method.md#two-deformable-layers); F's layer is built on M's contact face at F's pose.

To add a model: one subclass of :class:`FEModel` here, added to :data:`FE_MODELS`; a contact law
names it as its ``fe_twin``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from edem.raycast import RayCaster
from edem.springs import Placement, spring_geometry
from fem_reference.problem import DeformableCounterpart, RigidSurface
from geometries import fe_solids
from geometries.fe_solids import ContactRefinement
from geometries.errors import SolverError


@dataclass
class FEGeometry:
    """The solid and obstacle of one time point."""

    solid: Any  # geometries.fe_solids.FESolid
    obstacle: RigidSurface
    key: tuple  # equal keys -> identical mesh and obstacle
    warnings: list[str]
    #: (n, 3) per contact-face point (contact_surface's order) where its column crosses M's scene
    #: surface (FEModel.mobile_points_mm; fem_reference.scene_run sets it)
    mobile_points_mm: np.ndarray | None = None
    #: where the solid's surface was refined further (contact_refinement), or None
    refinement: ContactRefinement | None = None


def contact_surface(solid: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (n, 3) mm, triangles (m, 3), solid point index (n,)) of the solid's contact face."""
    faces = solid.faces(fe_solids.CONTACT_TAG)
    used = np.unique(faces)
    remap = np.full(len(solid.points_mm), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return solid.points_mm[used], remap[faces], used


class FEModel(ABC):
    """An FE model of the cartilage. Subclasses set the class attributes and the methods."""

    name: ClassVar[str]
    #: what it is, for messages
    what: ClassVar[str]
    #: whether it needs cartilage.thickness_mm
    needs_thickness: ClassVar[bool] = False
    #: whether the mesh changes with F's pose (else one mesh serves every time point)
    mesh_follows_pose: ClassVar[bool] = True
    #: whether the previous time point's bone translation, scaled with the load, is a good start
    warm_start_scales_with_load: ClassVar[bool] = True
    #: elastic solids in the mesh, each about the size of the one on M (for the size estimate)
    bodies: ClassVar[int] = 1

    @abstractmethod
    def build(self, scene: Any, mesh_size_mm: float, layers: int | None, caster: RayCaster, f_pose: Placement,
              obstacle: RigidSurface, pose_key: tuple, cache: dict, contact_mesh_size_mm: float | None = None) -> FEGeometry:
        """The solid of this time point (``cache`` keeps solids between time points); with
        ``contact_mesh_size_mm``, its surface refined to that size where the contact can reach
        (:func:`contact_refinement`; the models built on M's layer)."""
        ...

    def reach(self, scene: Any, gap_mm: np.ndarray, facing: np.ndarray) -> np.ndarray:
        """(n,) bool: contact-surface vertices that face F and can reach it under load: within
        :meth:`reach_depth_mm` of the closest approach (or of touching, where the bodies start apart)."""
        g0 = float(gap_mm[facing].min()) if facing.any() else 0.0
        return facing & (gap_mm <= max(g0, 0.0) + self.reach_depth_mm(scene))

    @abstractmethod
    def reach_depth_mm(self, scene: Any) -> float:
        """How far beyond the closest approach the contact can reach F (mm)."""
        ...

    @abstractmethod
    def sizing_surface(self, scene: Any, caster: RayCaster, f_pose: Placement) -> tuple[np.ndarray, float]:
        """M's triangles the solid is built on (mask) and its largest thickness (mm), for
        :mod:`fem_reference.sizing` before anything is meshed."""
        ...

    @abstractmethod
    def thickness_mm(self, scene: Any, solid: Any, used: np.ndarray, points_mm: np.ndarray) -> np.ndarray:
        """(n,) undeformed thickness under each contact-surface point (``used``: solid indices)."""
        ...

    @abstractmethod
    def spring_length_mm(self, thickness_mm: np.ndarray, gap_mm: np.ndarray) -> np.ndarray:
        """(n,) the spring length a contact-surface point stands for."""
        ...

    def mobile_points_mm(self, scene: Any, solid: Any, used: np.ndarray) -> np.ndarray:
        """(n, 3) where each contact-surface point's column (``used``: solid indices) crosses M's
        scene surface, the surface the springs live on: the comparisons measure the FE's area and
        pressure there. By default the bottom of the column (M's surface is the bonded face)."""
        return solid.points_mm[solid.bottom_vertex[used]]


def _spring_lengths(scene: Any, caster: RayCaster, f_pose: Placement) -> np.ndarray:
    """Per mobile triangle: the signed ray length of its spring (inf: no hit / no spring)."""
    geo = spring_geometry(scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2,
                          Placement.identity(scene.reference_point_mm), caster, f_pose,
                          scene.cartilage)
    lengths = np.full(scene.mobile.n_triangles, np.inf)
    lengths[scene.spring_triangle] = geo.spring_length_mm
    return lengths


def _snap_top_onto_fixed(solid: Any, caster: RayCaster, f_pose: Placement, window_mm: float,
                         obstacle: RigidSurface) -> Any:
    """Move the slab's top vertices onto F: along their extrusion direction (a ray cast from
    the bottom vertex, as the springs measure), or where that ray misses F (at the rim of F) onto
    the plane of the nearest triangle of F; intermediate layers follow in proportion. A vertex
    that would move by more than half its column keeps its place (the caller warns)."""
    pts = solid.points_mm
    nl = int(solid.layer.max())
    nv = int(np.sum(solid.layer == 0))
    bottom = pts[:nv]
    top = pts[nl * nv:]
    span = top - bottom
    h = np.linalg.norm(span, axis=1)
    d = span / h[:, None]
    rotation, translation = f_pose.affine()
    hits = caster.cast(bottom, d, window_mm, rotation=rotation, translation=translation)
    s = hits.spring_length_mm
    ok = np.isfinite(s) & (s > 0.0) & (np.abs(s - h) <= 0.5 * h)
    new_top = np.where(ok[:, None], bottom + s[:, None] * d, top)
    rest = np.flatnonzero(~ok)
    if rest.size:
        gap, nu = obstacle.gap_and_normal(top[rest])
        moved = top[rest] - gap[:, None] * nu
        near = np.abs(gap) <= 0.5 * h[rest]
        new_top[rest[near]] = moved[near]
    frac = (np.arange(nl + 1) / nl)[:, None, None]
    new = (bottom[None] + frac * (new_top - bottom)[None]).reshape(-1, 3)
    if not np.all(fe_solids.tet_volumes(new, solid.tets) > 0):
        return solid
    return replace(solid, points_mm=new)


def _build_solid(kind: str, build) -> tuple[Any, list[str]]:
    """The FE solid ``build()`` makes and the warnings it gave (rim triangles dropped...);
    SolverError when it cannot be built (its message names the triangles)."""
    import warnings as python_warnings

    with python_warnings.catch_warnings(record=True) as caught:
        python_warnings.simplefilter("always")
        try:
            solid = build()
        except ValueError as exc:
            raise SolverError(f"building the FE {kind} failed: {exc}") from None
    return solid, [str(w.message) for w in caught]


class SlabModel(FEModel):
    """The slab between M's candidate surface and F, touching F (twin of the threshold law)."""

    name = "slab"
    what = "twin of the threshold law"

    def build(self, scene, mesh_size_mm, layers, caster, f_pose, obstacle, pose_key, cache, contact_mesh_size_mm=None):
        key = ("slab", pose_key)
        warnings: list[str] = []
        cached = cache.get(key)
        if cached is not None:  # same pose of F: the same slab (its warnings were given once)
            return FEGeometry(cached, obstacle, key, warnings)
        cache.clear()
        h_max = float(scene.cartilage.max_spring_length_mm)
        lengths = _spring_lengths(scene, caster, f_pose)
        with np.errstate(invalid="ignore"):
            cand = np.isfinite(lengths) & (lengths <= h_max)
        bad = int(np.sum(cand & (lengths <= 0.0)))
        if bad:
            raise SolverError(
                f"{bad} springs are compressed past their length (h <= 0: the bodies interpenetrate); "
                "the FE slab needs M and F apart (use the layer model for overlapping bodies)")
        if not np.any(cand):
            raise SolverError(
                f"no spring is a candidate: no part of the fixed body lies within h_max = {h_max:g} "
                "mm of the mobile body along its normals (nothing to build the FE slab on)")
        solid, built_notes = _build_solid("slab", lambda: fe_solids.slab_solid(scene.mobile, lengths, h_max, mesh_size_mm, layers))
        warnings += built_notes
        solid = _snap_top_onto_fixed(solid, caster, f_pose, 2.0 * h_max, obstacle)
        pts, _, _ = contact_surface(solid)
        gap, _ = obstacle.gap_and_normal(pts)
        off = np.abs(gap) > 1e-6 * h_max
        if off.any():
            warnings.append(
                f"{int(off.sum())} of the slab's {len(pts)} contact-surface nodes could not be placed "
                f"on the fixed body (initial gap from {float(gap.min()):.3g} to "
                f"{float(gap.max()):.3g} mm; the slab is meant to touch it everywhere)")
        cache[key] = solid
        return FEGeometry(solid, obstacle, key, warnings)

    def reach_depth_mm(self, scene):
        # the slab starts touching F wherever it stands: its reach is the touching face, to round-off of its placing
        return 1e-3 * float(scene.cartilage.max_spring_length_mm)

    def sizing_surface(self, scene, caster, f_pose):
        from fem_reference.sizing import candidate_surface

        lengths = _spring_lengths(scene, caster, f_pose)
        mask = candidate_surface(lengths, float(scene.cartilage.max_spring_length_mm), scene.mobile.areas_mm2)
        return mask, float(lengths[mask].max()) if mask.any() else 0.0

    def thickness_mm(self, scene, solid, used, points_mm):
        return np.linalg.norm(points_mm - solid.points_mm[solid.bottom_vertex[used]], axis=1)

    def spring_length_mm(self, thickness_mm, gap_mm):
        return thickness_mm


class LayerModel(FEModel):
    """A uniform layer of the cartilage thickness bonded to M (twin of the gap laws)."""

    name = "layer"
    what = "twin of the gap laws"
    needs_thickness = True
    mesh_follows_pose = False
    warm_start_scales_with_load = False

    def build(self, scene, mesh_size_mm, layers, caster, f_pose, obstacle, pose_key, cache, contact_mesh_size_mm=None):
        if "solid" not in cache:
            cache["refinement"] = contact_refinement(scene, self.reach_depth_mm(scene), obstacle, contact_mesh_size_mm)
            cache["solid"], cache["solid_notes"] = _build_solid("layer", lambda: scene_layer_solid(scene, mesh_size_mm, layers, cache["refinement"]))
        warnings: list[str] = cache.pop("solid_notes", [])  # the construction's notes, given once
        pts, _, _ = contact_surface(cache["solid"])
        gap, _ = obstacle.gap_and_normal(pts)
        overlap = float(-gap.min()) if len(gap) else 0.0
        if overlap > 1e-9 * float(scene.cartilage.max_spring_length_mm):
            warnings.append(
                f"the layer overlaps the fixed body by up to {overlap:.3g} mm "
                f"({int(np.sum(gap < 0))} contact-surface nodes): it starts pre-compressed")
        return FEGeometry(cache["solid"], obstacle, ("layer", pose_key), warnings, refinement=cache["refinement"])

    def reach_depth_mm(self, scene: Any) -> float:
        """Half the layer's largest thickness."""
        return 0.5 * _largest_thickness_mm(scene)

    def thickness_mm(self, scene, solid, used, points_mm):
        # the column under each contact point (uniform: t; measured: the vertex's thickness)
        return np.linalg.norm(points_mm - solid.points_mm[solid.bottom_vertex[used]], axis=1)

    def mobile_points_mm(self, scene, solid, used):
        return _layer_mobile_points_mm(scene, solid, used)

    def sizing_surface(self, scene, caster, f_pose):
        return scene.mobile.areas_mm2 > 0, _largest_thickness_mm(scene)

    def spring_length_mm(self, thickness_mm, gap_mm):
        return thickness_mm + gap_mm


def contact_refinement(scene: Any, depth_mm: float, obstacle: RigidSurface, size_mm: float | None) -> ContactRefinement | None:
    """M's surface refined to ``size_mm`` where the contact can reach F (None: no size, none).

    The layer models' reach (:meth:`FEModel.reach`), judged on M's scene surface (the surface the
    layer is built on) before its layer is built: the points within ``depth_mm`` (half the
    cartilage) of M's closest approach to F (``obstacle``, F at the first time point's pose). For a
    uniform layer this is the reach of its contact face, whose gap to F is M's less the thickness;
    it holds for every later pose as long as F's approach stays within that depth (the run warns
    where the contact goes beyond it, :func:`fem_reference.scene_run.run_scene`).
    """
    if size_mm is None:
        return None
    gap, _ = obstacle.gap_and_normal(scene.mobile.vertices_mm)
    within_mm = float(np.nanmin(gap)) + depth_mm

    def reaches(points_mm: np.ndarray) -> np.ndarray:
        gap, _ = obstacle.gap_and_normal(points_mm)
        return np.isfinite(gap) & (gap <= within_mm)

    return ContactRefinement(float(size_mm), reaches)


def _layer_mobile_points_mm(scene: Any, solid: Any, used: np.ndarray) -> np.ndarray:
    """M's scene surface under the contact face of M's layer: the contact face itself where M's
    scene surface is its articular surface (a bone mesh under it: the layer stands below it),
    else the bone the layer stands on (the bonded face)."""
    layers = scene.cartilage.layers
    if layers is not None and layers.mobile.has_bone:
        return solid.points_mm[used]
    return solid.points_mm[solid.bottom_vertex[used]]


def _largest_thickness_mm(scene: Any) -> float:
    """The layer model's largest cartilage thickness: ``thickness_mm``, or M's measured/uniform layer."""
    layers = scene.cartilage.layers
    return float(scene.cartilage.thickness_mm) if layers is None else float(layers.mobile.thickness_mm.max())


def scene_layer_solid(scene: Any, mesh_size_mm: float, n_layers: int | None, contact: ContactRefinement | None = None) -> Any:
    """The layer model's solid: a uniform ``thickness_mm`` layer on M, or with per-side layers
    (:mod:`edem.thickness`) M's own: with a bone mesh the cartilage between M's articular surface
    and its bone (:func:`geometries.cartilage_solids.measured_layer_solid`), each vertex measured
    by the ray cast the springs' triangles are measured by (:func:`edem.thickness.measure_layer`,
    up to :data:`edem.thickness.BONE_SEARCH_MM`; where no bone lies below, the value M's unmeasured
    springs carry), or M's uniform layer. The layer model takes F rigid (:func:`fem_reference.settings.resolve_settings`
    refuses a layer on it); the two-layer model builds F's on this one's contact face. The
    construction's repairs are issued as warnings (the run's notes)."""
    layers = scene.cartilage.layers
    if layers is None:
        return fe_solids.layer_solid(scene.mobile, float(scene.cartilage.thickness_mm), mesh_size_mm, n_layers, contact)
    mobile = layers.mobile
    if not mobile.has_bone:
        return fe_solids.layer_solid(scene.mobile, float(mobile.thickness_mm.max()), mesh_size_mm, n_layers, contact)
    import warnings as python_warnings

    from geometries.cartilage_solids import measured_layer_solid

    solid, notes = measured_layer_solid(scene.mobile, scene.mobile.areas_mm2 > 0, _measured_thickness(mobile, mobile.bone),
                                        mesh_size_mm, n_layers, contact)
    for note in notes:  # collected by _build_solid as the construction's notes
        python_warnings.warn(note, stacklevel=2)
    return solid


def _measured_thickness(side: Any, bone: Any) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``thickness_at(vertices (k, 3) mm, inward directions (k, 3)) -> (k,) mm`` of a side's layer
    (:class:`edem.thickness.SideLayer`): measured to ``bone`` (placed as the vertices are) by the
    ray cast the springs' triangles are measured by (:func:`edem.thickness.measure_layer`), and
    where no bone lies below, the value the side's unmeasured triangles carry."""
    from edem.thickness import measure_layer
    from geometries.triangle_kernels import nearby_distance_mm

    unmeasured = side.thickness_mm[~side.measured]
    fallback = float(unmeasured.min()) if unmeasured.size else float(np.median(side.thickness_mm))
    on_bone_mm = 1e-9 * float(np.ptp(bone.vertices_mm, axis=0).max())  # round-off of the coordinates

    def thickness_at(vertices_mm: np.ndarray, inward: np.ndarray) -> np.ndarray:
        depth, measured = measure_layer(vertices_mm, -inward, bone)
        # a vertex on the layer's margin, where a tapered layer meets its bone, has no depth for
        # the ray to find: its thickness is 0, not the fallback (measured_layer_solid ends the solid there)
        on_bone = np.zeros(len(vertices_mm), bool)
        on_bone[~measured] = nearby_distance_mm(vertices_mm[~measured], bone.vertices_mm, bone.triangles) <= on_bone_mm
        return np.where(measured, depth, np.where(on_bone, 0.0, fallback))

    return thickness_at


def column_directions(solid: Any) -> tuple[np.ndarray, np.ndarray]:
    """(unit directions (k, 3), their points (k,)) of the columns under the solid's contact face,
    bone to contact face: the springs' rays through its points. A column of no height (a layer
    tapered to zero on its bone, :func:`geometries.fe_solids.extrude`) takes the contact face's
    vertex normal."""
    points, triangles, top = contact_surface(solid)
    column = solid.points_mm[top] - solid.points_mm[solid.bottom_vertex[top]]
    length = np.linalg.norm(column, axis=1)
    direction = fe_solids.vertex_normals(points, triangles)
    tall = length > 0.0
    direction[tall] = column[tall] / length[tall, None]
    return direction, top


def _facing_fixed(scene: Any, mobile: Any, f_pose: Placement) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Callable]:
    """Where the columns of M's layer (``mobile``), carried on as the springs' rays, meet F's
    articular surface at ``f_pose`` (F's scene surface with ``fixed_bone``; otherwise F's bone
    offset by ``fixed_thickness_mm``), looking ``max_spring_length_mm`` both ways.

    Returns M's contact-face points (k,), their unit column directions (k, 3), the points met
    (k, 3; NaN where the ray misses), F's articular triangle met (k,; -1) and F's
    ``thickness_at(vertices, inward) -> mm`` there (:func:`_measured_thickness` to F's bone at
    ``f_pose``, or the uniform layer)."""
    from geometries.cartilage_solids import offset_surface

    fixed = scene.cartilage.layers.fixed
    articular = scene.fixed if fixed.has_bone else offset_surface(scene.fixed, float(fixed.thickness_mm.max()))
    direction, top = column_directions(mobile)
    rotation, translation = f_pose.affine()
    hits = RayCaster(articular.vertices_mm, articular.triangles).cast(
        mobile.points_mm[top], direction, float(scene.cartilage.max_spring_length_mm), rotation=rotation, translation=translation)
    ok = np.isfinite(hits.spring_length_mm)
    points = np.full((len(top), 3), np.nan)
    points[ok] = mobile.points_mm[top[ok]] + hits.spring_length_mm[ok, None] * direction[ok]
    if fixed.has_bone:  # F's bone where F is at this time point
        thickness_at = _measured_thickness(fixed, replace(fixed.bone, vertices_mm=f_pose.points(fixed.bone.vertices_mm)))
    else:
        def thickness_at(vertices_mm: np.ndarray, inward: np.ndarray) -> np.ndarray:
            return np.full(len(vertices_mm), float(fixed.thickness_mm.max()))
    return top, direction, points, np.where(ok, hits.triangle, -1), thickness_at


def fixed_has_cartilage(scene: Any) -> bool:
    """Whether the scene gives F a cartilage layer of its own (``[geometry] fixed_bone`` or
    ``[cartilage] fixed_thickness_mm > 0``)."""
    layers = scene.cartilage.layers
    return layers is not None and (layers.fixed.has_bone or float(layers.fixed.thickness_mm.max()) > 0.0)


def _cache_mobile_layer(cache: dict, scene, mesh_size_mm, layers, depth_mm: float, obstacle: RigidSurface,
                        contact_mesh_size_mm: float | None) -> list[str]:
    """M's layer solid (as :class:`LayerModel` builds it, refined within ``depth_mm`` of the contact
    to ``contact_mesh_size_mm``), built once per run into ``cache["mobile"]`` with its refinement
    (it does not depend on F's pose); the warnings of building it, once."""
    if "mobile" in cache:
        return []
    cache["refinement"] = contact_refinement(scene, depth_mm, obstacle, contact_mesh_size_mm)
    cache["mobile"], notes = _build_solid("layer", lambda: scene_layer_solid(scene, mesh_size_mm, layers, cache["refinement"]))
    return list(notes)


class TwoLayerModel(FEModel):
    """M's layer (as :class:`LayerModel` builds it) and F's, both elastic, each bonded to its bone,
    in frictionless contact (docs/method.md#two-deformable-layers).

    F's layer is built on M's contact face: each of its points is carried along its column (M's
    smoothed normal, the springs' ray) onto F's articular surface at the time point's pose (F's
    scene surface with ``fixed_bone``; otherwise F's bone offset by ``fixed_thickness_mm``), and F's
    columns go from there down F's smoothed normals to its bone (measured, or the uniform
    thickness) (:func:`geometries.cartilage_solids.opposing_layer_solid`). The rays look as far as
    the springs' (``max_spring_length_mm``, both ways); M's contact triangles whose rays miss F
    become free faces. Both layers have the scene's cartilage."""

    name = "two-layer"
    what = "twin of the gap laws with cartilage on both bones"
    needs_thickness = True
    warm_start_scales_with_load = False
    bodies = 2

    def build(self, scene, mesh_size_mm, layers, caster, f_pose, obstacle, pose_key, cache, contact_mesh_size_mm=None):
        key = ("two-layer", pose_key)
        warnings = _cache_mobile_layer(cache, scene, mesh_size_mm, layers, self.reach_depth_mm(scene), obstacle, contact_mesh_size_mm)
        if cache.get("key") != key:
            solid, notes = _build_solid("two-layer solid", lambda: self._paired(scene, cache["mobile"], f_pose, layers))
            cache.update(key=key, solid=solid)
            warnings += notes
        solid = cache["solid"]
        counterpart = DeformableCounterpart.from_solid(solid, float(scene.cartilage.youngs_modulus_mpa),
                                                       float(scene.cartilage.poissons_ratio))
        pts, _, _ = contact_surface(solid)
        gap, _ = counterpart.gap_and_normal(pts)
        overlap = float(-gap.min()) if len(gap) else 0.0
        if overlap > 1e-9 * float(scene.cartilage.max_spring_length_mm):
            warnings.append(f"the two layers overlap by up to {overlap:.3g} mm ({int(np.sum(gap < 0))} contact-surface "
                            "nodes): they start pre-compressed")
        return FEGeometry(solid, counterpart, key, warnings, refinement=cache["refinement"])

    @staticmethod
    def _paired(scene: Any, mobile: Any, f_pose: Placement, n_layers: int | None) -> Any:
        """M's layer and F's built on its contact face (F at ``f_pose``); the build's notes are
        issued as warnings (collected by :func:`_build_solid`)."""
        from geometries.cartilage_solids import opposing_layer_solid

        top, _direction, points, _triangle, thickness_at = _facing_fixed(scene, mobile, f_pose)
        facing = np.full_like(mobile.points_mm, np.nan)
        facing[top] = points

        import warnings as python_warnings

        solid, notes = opposing_layer_solid(mobile, facing, thickness_at, n_layers)
        for note in notes:  # collected by _build_solid as the construction's notes
            python_warnings.warn(note, stacklevel=2)
        return solid

    def reach_depth_mm(self, scene: Any) -> float:
        """Half the two layers' largest thicknesses together."""
        return 0.5 * (_largest_thickness_mm(scene) + float(scene.cartilage.layers.fixed.thickness_mm.max()))

    def sizing_surface(self, scene, caster, f_pose):
        # F's layer stands on M's contact face: as many columns as M's (bodies = 2), the thicker layer's
        return scene.mobile.areas_mm2 > 0, max(_largest_thickness_mm(scene), float(scene.cartilage.layers.fixed.thickness_mm.max()))

    def thickness_mm(self, scene, solid, used, points_mm):
        # both columns: M's under the contact point and F's under its partner
        x, bottom, partner = solid.points_mm, solid.bottom_vertex, solid.partner[used]
        return np.linalg.norm(points_mm - x[bottom[used]], axis=1) + np.linalg.norm(x[partner] - x[bottom[partner]], axis=1)

    def mobile_points_mm(self, scene, solid, used):
        return _layer_mobile_points_mm(scene, solid, used)

    def spring_length_mm(self, thickness_mm, gap_mm):
        return thickness_mm + gap_mm


class LumpedLayerModel(FEModel):
    """Both layers summed into one on M's bone, against F's bone taken rigid: the FE of the lumped
    layer (``[cartilage] thin_layer_stack = "lumped"``), the reference of the lumping error
    (docs/method.md#two-deformable-layers).

    Each column of M's layer (as :class:`LayerModel` builds it) goes on from M's bone along its
    direction for t_M + t_F, t_F F's layer along the same line: from where the column, carried on
    as the springs' ray, meets F's articular surface on to F's bone (measured, or F's uniform
    layer; where it meets no F, F's uniform layer, or nothing for a measured F, whose cartilage
    ends at its margin). So the lumped layer's face stands t_F beyond M's articular surface, its
    gap to F's bone along the column is the articular surfaces' gap (the springs' h_b - T), and it
    touches F's bone where the two layers touch. One material (the scene's), bonded on M's bone
    only, the other face free against F's bone."""

    name = "lumped"
    what = "both layers summed into one on M, F's bone rigid (the lumped layer's twin)"
    needs_thickness = True
    warm_start_scales_with_load = False

    def build(self, scene, mesh_size_mm, layers, caster, f_pose, obstacle, pose_key, cache, contact_mesh_size_mm=None):
        key = ("lumped", pose_key)
        warnings = _cache_mobile_layer(cache, scene, mesh_size_mm, layers, self.reach_depth_mm(scene), obstacle, contact_mesh_size_mm)
        if cache.get("key") != key:
            (solid, on_mobile), _ = _build_solid("lumped layer", lambda: self._summed(scene, cache["mobile"], f_pose, mesh_size_mm, layers))
            cache.update(key=key, solid=solid, on_mobile=on_mobile)
        fixed = scene.cartilage.layers.fixed
        bone = fixed.bone if fixed.has_bone else scene.fixed  # without a bone mesh F's scene surface is its bone
        bone_obstacle = RigidSurface(f_pose.points(bone.vertices_mm), bone.triangles, candidates=16)
        pts, _, _ = contact_surface(cache["solid"])
        gap, _ = bone_obstacle.gap_and_normal(pts)
        overlap = float(-gap.min()) if len(gap) else 0.0
        if overlap > 1e-9 * float(scene.cartilage.max_spring_length_mm):
            warnings.append(f"the lumped layer overlaps F's bone by up to {overlap:.3g} mm ({int(np.sum(gap < 0))} contact-surface "
                            "nodes): it starts pre-compressed")
        return FEGeometry(cache["solid"], bone_obstacle, key, warnings, cache["on_mobile"], cache["refinement"])

    @staticmethod
    def _summed(scene: Any, mobile: Any, f_pose: Placement, mesh_size_mm: float, n_layers: int | None) -> tuple[Any, np.ndarray]:
        """The columns of M's layer lengthened by F's thickness where they meet F (the class
        docstring), and per point of its contact face (contact_surface's order) where its column
        crosses M's scene surface: t_M up from M's bone with a bone mesh (M's articular surface),
        else the bone."""
        top, direction, points, triangle, thickness_at = _facing_fixed(scene, mobile, f_pose)
        fixed = scene.cartilage.layers.fixed
        t_fixed = np.full(len(top), 0.0 if fixed.has_bone else float(fixed.thickness_mm.max()))
        hit = triangle >= 0
        t_fixed[hit] = thickness_at(points[hit], direction[hit])  # on along the ray, through F's layer to its bone
        points_mm, triangles, _ = contact_surface(mobile)  # (its points are ``top``, in that order)
        bone = mobile.points_mm[mobile.bottom_vertex[top]]
        total = np.linalg.norm(points_mm - bone, axis=1) + t_fixed
        size = mesh_size_mm if mesh_size_mm is not None else fe_solids.mean_edge(points_mm, triangles)
        solid = fe_solids.extrude("lumped-layer", bone, triangles, direction, total, fe_solids.layers_for(n_layers, float(total.max()), size))
        from scipy.spatial import cKDTree

        face, _, _ = contact_surface(solid)
        _, column = cKDTree(bone + total[:, None] * direction).query(face)  # the same floats: each face point's column
        on_mobile = points_mm if scene.cartilage.layers.mobile.has_bone else bone
        return solid, on_mobile[column]

    reach_depth_mm = TwoLayerModel.reach_depth_mm  # the summed layer reaches as the two do

    def sizing_surface(self, scene, caster, f_pose):
        return scene.mobile.areas_mm2 > 0, _largest_thickness_mm(scene) + float(scene.cartilage.layers.fixed.thickness_mm.max())

    def thickness_mm(self, scene, solid, used, points_mm):
        return np.linalg.norm(points_mm - solid.points_mm[solid.bottom_vertex[used]], axis=1)

    def spring_length_mm(self, thickness_mm, gap_mm):
        return thickness_mm + gap_mm


#: every FE model by name (``[fe] model``, ``edem fe --model``)
FE_MODELS: dict[str, FEModel] = {m.name: m for m in (SlabModel(), LayerModel(), TwoLayerModel(), LumpedLayerModel())}
