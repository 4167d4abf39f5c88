"""Measured cartilage thickness (docs/method.md#measured-cartilage-thickness): a subchondral bone
surface under each body's articular surface, as OpenSim JAM's contact meshes carry.

Each side has a cartilage layer between its bone and its articular surface:

* with a bone mesh (``[geometry] mobile_bone`` / ``fixed_bone``, or the bones a built-in ankle
  builds under its cartilage, ``[geometry] cartilage = true``) the side's scene surface is its
  articular surface, and the layer's thickness is measured per triangle: from the triangle's
  centroid along minus its normal (into the body) to the bone, by the same Embree ray cast as the
  springs (:class:`edem.raycast.RayCaster`), up to :data:`BONE_SEARCH_MM`. Where that ray finds no
  bone (a rim of cartilage beyond the bone mesh, a hole), the side's ``[cartilage]
  <side>_thickness_mm`` is used, or the median of the side's measured values without it;
* without a bone mesh the side's scene surface is its bone, and the layer is uniform,
  ``[cartilage] mobile_thickness_mm`` / ``fixed_thickness_mm`` thick (0: rigid, no cartilage).

A spring of M (its ray meets F's triangle j) then carries the two layers in series, total
thickness T = t_M + t_F[j], and its ray length h between the two scene surfaces becomes the
bone-to-bone length h_b = h + t_M [M has a bone mesh] + t_F[j] [F has a bone mesh]: the
articular surfaces meet at h_b = T. The contact laws take h_b as the spring length and T as the
spring's undeformed thickness (:class:`Layers.along_rays`), so the gap law is
p = E' (T - h_b + delta) / T: k = E' / (t_M + t_F) per unit area.

Pure functions on arrays; the scene keys are read here (:func:`scene_layers`) so that the scene
loader only calls one function.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometries.errors import InputError
from edem.raycast import RayCaster
from geometries.surface import TriangleSurface

#: how far below an articular triangle its bone is looked for (mm): OpenSim JAM's default
#: max_thickness of a contact mesh (0.01 m); cartilage is at most about 6 mm thick in the knee
BONE_SEARCH_MM = 10.0
#: the scene keys that switch measured (or per-side) thickness on
GEOMETRY_KEYS = ("mobile_bone", "fixed_bone")
CARTILAGE_KEYS = ("mobile_thickness_mm", "fixed_thickness_mm")
SIDES = ("mobile", "fixed")


@dataclass(frozen=True)
class SideLayer:
    """The cartilage layer of one body, per triangle of its scene surface."""

    thickness_mm: np.ndarray  # (k,) per triangle (or per spring for M)
    measured: np.ndarray  # (k,) bool: measured to the bone (False: the side's uniform or fallback value)
    area_mm2: np.ndarray  # (k,) of the triangles (for area shares)
    has_bone: bool  # the scene surface is the articular surface (a bone mesh under it); False: it is the bone
    bone: TriangleSurface | None = None  # the bone mesh (facing the articular surface), for the FE layer's per-vertex thickness


@dataclass(frozen=True)
class Layers:
    """Both bodies' layers: M's per spring, F's per triangle of F (docs/method.md#measured-cartilage-thickness)."""

    mobile: SideLayer
    fixed: SideLayer

    def along_rays(self, spring_length_mm: np.ndarray, fixed_triangle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bone-to-bone length h_b and total thickness T of every spring (mm, both (n,)).

        ``spring_length_mm`` (n,) the ray lengths between the scene surfaces (+inf: no hit) and
        ``fixed_triangle`` (n,) F's triangle each ray meets (-1: none). Where a ray meets nothing,
        F's part of T is the median of F's layer (T stays finite for the coupled layer's band)."""
        hit = fixed_triangle >= 0
        fixed = np.where(hit, self.fixed.thickness_mm[np.where(hit, fixed_triangle, 0)], float(np.median(self.fixed.thickness_mm)))
        total = self.mobile.thickness_mm + fixed
        bone_to_bone = spring_length_mm + (self.mobile.thickness_mm if self.mobile.has_bone else 0.0) + (fixed if self.fixed.has_bone else 0.0)
        return bone_to_bone, total

    @property
    def uniform_offset_mm(self) -> float:
        """Largest ray length h at which the articular surfaces meet: the uniform layers' sum."""
        return sum(float(side.thickness_mm.max()) for side in (self.mobile, self.fixed) if not side.has_bone)


def measure_layer(
    centroid_mm: np.ndarray, normal: np.ndarray, bone: TriangleSurface, search_mm: float = BONE_SEARCH_MM
) -> tuple[np.ndarray, np.ndarray]:
    """Thickness from articular triangles to their bone, along minus their normals.

    Parameters
    ----------
    centroid_mm, normal : (k, 3) float
        The articular triangles' centroids (mm) and unit normals (out of the body, towards the
        joint); zero rows are triangles without a normal (never measured).
    bone : TriangleSurface
        The subchondral bone, normals facing the articular surface (:func:`orient_bone`).
    search_mm : float
        Farthest bone counted (mm).

    Returns
    -------
    thickness_mm : (k,) float
        Distance to the bone; NaN where none lies within (0, search_mm].
    measured : (k,) bool
    """
    inward = -np.asarray(normal, float)
    # The caster's window is signed, (-h, h] about the origin, nearest hit first: centred half-way
    # down, it looks at depths (0, search_mm] only, so a bone beside the rim in front of the
    # articular surface cannot hide the bone below it.
    half = 0.5 * float(search_mm)
    hits = RayCaster(bone.vertices_mm, bone.triangles).cast(np.asarray(centroid_mm, float) + half * inward, inward, half)
    depth = hits.spring_length_mm + half
    measured = np.isfinite(depth) & (depth > 0.0)
    return np.where(measured, depth, np.nan), measured


def orient_bone(bone: TriangleSurface, articular: TriangleSurface, key: str) -> TriangleSurface:
    """The bone's normals turned to face its articular surface (the rays into the body then meet
    its front faces, :mod:`edem.raycast`)."""
    from geometries.repair import orient_towards

    return orient_towards(bone, articular.vertices_mm, key=key, near_mm=BONE_SEARCH_MM)


def side_layer(
    centroid_mm: np.ndarray, normal: np.ndarray, area_mm2: np.ndarray, bone: TriangleSurface | None,
    uniform_mm: float | None, what: str, notes: list[str],
) -> SideLayer:
    """One side's layer: measured to ``bone`` (misses take ``uniform_mm``, or the measured median
    without it), or ``uniform_mm`` everywhere without a bone. ``what`` names the side in notes."""
    k = centroid_mm.shape[0]
    if bone is None:
        return SideLayer(np.full(k, float(uniform_mm)), np.zeros(k, bool), area_mm2, False)
    thickness, measured = measure_layer(centroid_mm, normal, bone)
    if not np.any(measured):
        raise InputError(
            f"no {what} triangle has its bone within {BONE_SEARCH_MM:g} mm below it (along minus its normal)",
            key=f"geometry.{what}_bone", expected=f"the subchondral bone under the {what} articular surface, in the same frame and units",
        )
    fallback = float(np.median(thickness[measured])) if uniform_mm is None else float(uniform_mm)
    missed = float(area_mm2[~measured].sum() / area_mm2.sum())
    if missed > 0.0:
        notes.append(
            f"{what} cartilage: {100 * missed:.1f} % of the articular area has no bone within {BONE_SEARCH_MM:g} mm below it; "
            f"it takes {fallback:.3g} mm ({'the median measured thickness' if uniform_mm is None else f'{what}_thickness_mm'})"
        )
    return SideLayer(np.where(measured, thickness, fallback), measured, area_mm2, True, bone)


def builtin_bones(geometry: dict[str, Any]) -> bool:
    """Whether a scene's ``[geometry]`` asks a built-in builder for bones under its cartilage
    (:func:`geometries.builders.builds_bones`: the ankles with ``cartilage = true``, their default)."""
    from geometries.builders import builds_bones

    return isinstance(geometry, dict) and isinstance(geometry.get("builtin"), str) and builds_bones(geometry["builtin"], geometry)


def uses_layers(data: dict[str, Any]) -> bool:
    """Whether a parsed scene asks for per-side layers (a bone mesh, a built-in ankle's bones or a per-side thickness)."""
    geometry, cartilage = data.get("geometry", {}), data.get("cartilage", {})
    return (isinstance(geometry, dict) and any(k in geometry for k in GEOMETRY_KEYS)) or builtin_bones(geometry) or (
        isinstance(cartilage, dict) and any(k in cartilage for k in CARTILAGE_KEYS)
    )


def build_layers(
    mobile: TriangleSurface,
    fixed: TriangleSurface,
    spring_triangle: np.ndarray,
    bones: dict[str, TriangleSurface | None],
    uniform_mm: dict[str, float | None],
    notes: list[str],
) -> Layers:
    """Both layers of a scene: M's per spring (``spring_triangle`` indexes M's triangles), F's per
    triangle. ``bones`` and ``uniform_mm`` by side ("mobile", "fixed"); a side without a bone
    needs its uniform thickness (InputError naming the key otherwise)."""
    for side in SIDES:
        if bones[side] is None and uniform_mm[side] is None:
            raise InputError(
                f"the {side} side has neither a bone mesh nor a uniform cartilage thickness",
                key=f"cartilage.{side}_thickness_mm",
                expected=f"{side}_thickness_mm in mm (>= 0; 0: no cartilage on that side), or [geometry] {side}_bone",
            )
    m = spring_triangle
    layers = Layers(
        side_layer(mobile.centroids_mm[m], mobile.unit_normals[m], mobile.areas_mm2[m], bones["mobile"], uniform_mm["mobile"], "mobile", notes),
        side_layer(fixed.centroids_mm, fixed.unit_normals, fixed.areas_mm2, bones["fixed"], uniform_mm["fixed"], "fixed", notes),
    )
    if float(layers.mobile.thickness_mm.min()) + float(layers.fixed.thickness_mm.min()) <= 0.0:
        raise InputError(
            "the total cartilage thickness is 0 somewhere (both layers 0 mm)", key="cartilage.mobile_thickness_mm, cartilage.fixed_thickness_mm",
            expected="a layer > 0 mm on at least one side",
        )
    return layers


def scene_layers(
    data: dict[str, Any], path: Path, mobile: TriangleSurface, fixed: TriangleSurface, spring_triangle: np.ndarray,
    window_mm: float, notes: list[str], built_bones: dict[str, TriangleSurface | None] | None = None,
) -> Layers | None:
    """The layers a parsed scene file asks for (README.md#scene-files), or None.

    Reads ``[geometry] mobile_bone, fixed_bone`` (mesh files beside the scene, in the scene's
    ``units``, placed as ``mobile``/``fixed``), or takes ``built_bones`` by side (the bones a
    built-in ankle built under its cartilage), and ``[cartilage] mobile_thickness_mm,
    fixed_thickness_mm``. Either bone is oriented and measured alike. InputError naming the
    file and key for a combination that cannot be read (``thickness_mm`` beside them, a bone
    file with a built-in geometry or an OpenSim model, a ray window that cannot see the
    articular surfaces meet).
    """
    if not uses_layers(data):
        return None
    from edem.tables import SceneTable

    file = str(path)
    geometry, cartilage = data["geometry"], data["cartilage"]
    if "thickness_mm" in cartilage:
        raise InputError(
            "thickness_mm (one combined thickness) cannot be combined with per-side layers"
            + (" (the built-in ankle's cartilage, geometry.cartilage = true)" if built_bones else ""),
            file=file, key="cartilage.thickness_mm",
            expected="mobile_thickness_mm and fixed_thickness_mm (or a bone mesh per side) without thickness_mm"
            + ("; or geometry.cartilage = false for the thesis's geometry without cartilage" if built_bones else ""),
        )
    if ("builtin" in geometry or "opensim" in data) and any(k in geometry for k in GEOMETRY_KEYS):
        raise InputError(
            "bone meshes go with mesh files only", file=file, key=f"geometry.{next(k for k in GEOMETRY_KEYS if k in geometry)}",
            expected="[geometry] mobile and fixed mesh files beside mobile_bone / fixed_bone (a built-in ankle builds its own bones: geometry.cartilage = true)",
        )
    table = SceneTable(cartilage, file, "cartilage", None)
    uniform = {side: table.optional_number(f"{side}_thickness_mm", nonnegative=True, high=BONE_SEARCH_MM,
                                           what=f"the {side} cartilage thickness in mm (>= 0 and < {BONE_SEARCH_MM:g})")
               for side in SIDES}
    bones: dict[str, TriangleSurface | None] = {}
    units = geometry.get("units", "mm")
    for side, articular in zip(SIDES, (mobile, fixed)):
        key = f"geometry.{side}_bone"
        if built_bones is not None:
            bone = built_bones[side]
        elif f"{side}_bone" in geometry:
            from geometries.repair import prepare_surface

            name = SceneTable(geometry, file, "geometry", None).string(f"{side}_bone")
            bone = prepare_surface(path.parent / name, units=units, key=key, name=f"{side}_bone", refuse_units=True)
        else:
            bone = None
        bones[side] = None if bone is None else orient_bone(bone, articular, key)
    try:
        layers = build_layers(mobile, fixed, spring_triangle, bones, uniform, notes)
    except InputError as exc:
        raise InputError(exc.problem, file=file, key=exc.key, expected=exc.expected) from None
    if window_mm <= layers.uniform_offset_mm:
        raise InputError(
            f"the ray window h_max = {window_mm:g} mm does not reach where the articular surfaces meet "
            f"(h = {layers.uniform_offset_mm:g} mm between the scene surfaces: the uniform layers)",
            file=file, key="cartilage.max_spring_length_mm", expected=f"h_max > {layers.uniform_offset_mm:g} mm",
        )
    return layers


def _distribution(side: SideLayer) -> dict[str, Any]:
    share = float(side.area_mm2[side.measured].sum() / side.area_mm2.sum()) if side.area_mm2.sum() > 0 else 0.0
    return {
        "source": "bone" if side.has_bone else "uniform",
        "min_mm": float(side.thickness_mm.min()),
        "median_mm": float(np.median(side.thickness_mm)),
        "max_mm": float(side.thickness_mm.max()),
        "measured_area_share": share,
        "uniform_area_share": 1.0 - share,
    }


def thickness_summary(layers: Layers | None) -> dict[str, Any]:
    """summary.json's ``cartilage_thickness`` (docs/result-format.md): per side, where the layer
    comes from ("bone" or "uniform"), min/median/max thickness (mm; M over its springs, F over its
    triangles) and the area shares measured and uniform (a bone side's misses count as uniform).
    Empty without layers."""
    if layers is None:
        return {}
    return {"cartilage_thickness": {"mobile": _distribution(layers.mobile), "fixed": _distribution(layers.fixed)}}


def array_layers(
    mobile: TriangleSurface,
    fixed: TriangleSurface,
    spring_triangle: np.ndarray,
    bones: dict[str, tuple[np.ndarray, np.ndarray] | None],
    uniform_mm: dict[str, float | None],
    window_mm: float,
    notes: list[str],
) -> Layers | None:
    """:func:`scene_layers` for meshes in memory (:meth:`edem.scene.Scene.from_arrays`): ``bones``
    by side as (vertices (m, 3) mm, triangles (k, 3) int) or None. None when nothing is given."""
    if all(bones[s] is None and uniform_mm[s] is None for s in SIDES):
        return None
    surfaces: dict[str, TriangleSurface | None] = {}
    for side, articular in zip(SIDES, (mobile, fixed)):
        given = bones[side]
        if given is None:
            surfaces[side] = None
            continue
        vertices, triangles = (np.asarray(a) for a in given)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.isfinite(vertices).all() or triangles.ndim != 2 or triangles.shape[1] != 3:
            raise InputError(f"shapes {vertices.shape}, {triangles.shape}", file="<arrays>", key=f"{side}_bone",
                             expected="(vertices (m, 3) finite mm, triangles (k, 3) int)")
        bone = TriangleSurface(vertices.astype(np.float64), triangles.astype(np.int64), name=f"{side}_bone", source="<arrays>")
        surfaces[side] = orient_bone(bone, articular, f"{side}_bone")
    layers = build_layers(mobile, fixed, spring_triangle, surfaces, uniform_mm, notes)
    if window_mm <= layers.uniform_offset_mm:
        raise InputError(f"the ray window {window_mm:g} mm does not reach where the articular surfaces meet", file="<arrays>",
                         key="max_spring_length_mm", expected=f"> {layers.uniform_offset_mm:g} mm (the uniform layers)")
    return layers
