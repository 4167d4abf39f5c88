"""The measured cartilage solid of a real joint (docs/method.md#the-fe-layer-on-measured-thickness).

A segmented joint gives a body's articular surface and, beneath it, its subchondral bone
(``[geometry] mobile_bone``): the cartilage is the solid between them. :func:`measured_layer_solid`
builds it as prisms from the articular surface down its vertex normals, smoothed over
:data:`DIRECTION_SMOOTHING_MM` (:func:`smooth_directions`), by each vertex's thickness measured
along them (the caller measures: :mod:`fem_reference.models`), three tetrahedra per prism split
as in :mod:`geometries.fe_solids` (whose extrusion helpers it uses): the bonded face (tag 1) is
the bone side, the contact face (tag 2) the articular surface itself, so the FE contact starts
exactly where the springs' does. :func:`offset_surface` moves a surface along its vertex normals
(a bone plus a uniform cartilage layer taken as rigid).

Segmented surfaces end in slivers: rim triangles whose vertex normals lean far from their own,
and a thickness that jumps from vertex to vertex. Their prisms would turn inside out; instead of
refusing, the solid repairs them (:func:`measured_layer_solid`): thickness and direction are
smoothed where prisms invert, and rim triangles that still invert are dropped, both stated in the
notes; only an interior prism that no smoothing rights is refused (ValueError naming where).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from geometries.fe_solids import (
    ContactRefinement, FESolid, extrude, inverted_prisms, layers_for, levels_for, mean_edge, refine, rim_triangles, submesh,
    vertex_normals,
)
from geometries.surface import TriangleSurface

__all__ = ["measured_layer_solid", "offset_surface", "opposing_layer_solid", "smooth_directions"]

#: smoothing passes before a rim triangle is dropped: each pass averages the thickness of an
#: inverting prism's corners with their neighbours (one ring further per pass)
_SMOOTHING_ROUNDS = 30
#: the columns go down the vertex normals smoothed over about this distance (mm): on a segmented
#: surface neighbouring normals differ by several degrees from facet to facet, and over a column
#: 5-10 times taller than the facets' edges that tilts neighbouring columns into each other; a
#: direction field smooth on the cartilage's own scale keeps every prism upright at every mesh level
DIRECTION_SMOOTHING_MM = 1.0
#: a vertex whose thickness is at most this fraction of the surface's extent lies on its bone (the
#: round-off of the coordinates): the margin of a layer tapered to zero, where its column is one
#: point (:func:`geometries.fe_solids.extrude`; docs/method.md#the-fe-layer-on-measured-thickness)
ZERO_THICKNESS_FRACTION = 1e-9


def offset_surface(surface: TriangleSurface, distance_mm: float, name: str = "") -> TriangleSurface:
    """``surface`` moved by ``distance_mm`` along its area-weighted vertex normals (its triangles'
    orientation: towards the other body for a scene surface). Used for a bone plus a uniform
    rigid layer; a concave fold tighter than the distance would turn inside out (not checked
    here: the caller keeps the region it needs)."""
    normals = vertex_normals(surface.vertices_mm, surface.triangles)
    return TriangleSurface(surface.vertices_mm + float(distance_mm) * normals, surface.triangles.copy(),
                           name=name or f"{surface.name}+{distance_mm:g}mm", source=surface.source)


def _one_ring_mean(values: np.ndarray, triangles: np.ndarray, nv: int) -> np.ndarray:
    """Mean of each vertex's value and its edge neighbours' (vectorised over the edges)."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    total = values.astype(float).copy()
    count = np.ones(nv)
    np.add.at(total, edges[:, 0], values[edges[:, 1]])
    np.add.at(total, edges[:, 1], values[edges[:, 0]])
    np.add.at(count, edges[:, 0], 1.0)
    np.add.at(count, edges[:, 1], 1.0)
    return total / count


def _inverted(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray, thickness: np.ndarray, n_layers: int) -> np.ndarray:
    """(n_tri,) bool: triangles with a tetrahedron of non-positive volume in any of their
    ``n_layers`` stacked prisms down to ``vertices - thickness * normals``."""
    bottom = vertices - thickness[:, None] * normals
    step = thickness / n_layers
    bad = np.zeros(len(triangles), bool)
    for k in range(n_layers):
        bad |= inverted_prisms(bottom + (k * step)[:, None] * normals, triangles, normals, step)
    return bad


def smooth_directions(vertices: np.ndarray, triangles: np.ndarray, radius_mm: float = DIRECTION_SMOOTHING_MM) -> np.ndarray:
    """(n, 3) unit column directions: the area-weighted vertex normals averaged with their edge
    neighbours (radius / mean edge)^2 times (a diffusion that reaches about ``radius_mm``)."""
    directions = vertex_normals(vertices, triangles)
    rounds = int(np.ceil((float(radius_mm) / mean_edge(vertices, triangles)) ** 2))
    for _ in range(rounds):
        mean = np.column_stack([_one_ring_mean(directions[:, k], triangles, len(vertices)) for k in range(3)])
        directions = mean / np.linalg.norm(mean, axis=1)[:, None]
    return directions


def _smooth_inverted(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray, thickness: np.ndarray,
                     n_layers: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Thickness and extrusion directions averaged over the corners of inverted prisms (with their
    edge neighbours), up to :data:`_SMOOTHING_ROUNDS` times. A thickness that jumps between
    neighbours (a segmentation step) tilts the bone-side face past the prism's sides; a sliver's
    vertex normal leans past its neighbours'. Returns the thickness, the directions, the triangles
    still inverted and those smoothed under."""
    thickness, normals = thickness.copy(), normals.copy()
    touched = np.zeros(len(triangles), bool)
    for _ in range(_SMOOTHING_ROUNDS):
        bad = _inverted(vertices, triangles, normals, thickness, n_layers)
        if not bad.any():
            return thickness, normals, bad, touched
        touched |= bad
        corners = np.unique(triangles[bad])
        thickness[corners] = _one_ring_mean(thickness, triangles, len(vertices))[corners]
        mean = np.column_stack([_one_ring_mean(normals[:, k], triangles, len(vertices)) for k in range(3)])
        normals[corners] = mean[corners] / np.linalg.norm(mean[corners], axis=1)[:, None]
    return thickness, normals, _inverted(vertices, triangles, normals, thickness, n_layers), touched


def measured_layer_solid(
    articular: TriangleSurface,
    mask: np.ndarray,
    thickness_at: Callable[[np.ndarray, np.ndarray], np.ndarray],
    mesh_size_mm: float | None = None,
    layers_through_thickness: int | None = None,
    contact: ContactRefinement | None = None,
) -> tuple[FESolid, list[str]]:
    """The cartilage between an articular surface and its bone, bonded to the bone.

    Parameters
    ----------
    articular : TriangleSurface
        The articular surface (mm), normals out of the body (towards the joint).
    mask : (n_triangles,) bool
        The triangles the solid is built under (e.g. those that can reach the other body).
    thickness_at : callable
        ``thickness_at(vertices (k, 3) mm, inward unit directions (k, 3)) -> (k,) mm``: the
        cartilage thickness below each vertex along the direction (measured to the bone; finite,
        > 0). The directions are the vertex normals smoothed (:func:`smooth_directions`).
    mesh_size_mm : float, optional
        Target edge length: the surface is midpoint-subdivided (flat: on its own facets) until its
        mean edge is at most this; every vertex then has its thickness measured.
    layers_through_thickness : int, optional
        Element layers (default: ceil(largest thickness / mesh size)).
    contact : ContactRefinement, optional
        Where the contact can reach (judged on the articular vertices), the surface is refined
        further, to its size.

    Returns
    -------
    solid : FESolid
        Points of layer n (the contact face, tag 2) are the articular vertices (and the midpoints
        of a subdivision); layer 0 (bonded, tag 1) lies the thickness below them.
        ``bottom_vertex`` indexes the (subdivided) surface the solid stands on.
    notes : list of str
        The repairs made (smoothed vertices, dropped rim triangles), for the run's warnings.
    """
    mask = np.asarray(mask, bool) & (articular.areas_mm2 > 0.0)
    if not mask.any():
        raise ValueError("measured_layer_solid: no triangle to build the cartilage under")
    # subdivided first, so that every vertex of the solid has its own measured thickness
    verts, tris, _ = submesh(articular, mask)
    size = mesh_size_mm if mesh_size_mm is not None else mean_edge(verts, tris)
    verts, tris, _ = refine(verts, tris, [], levels_for(mesh_size_mm, verts, tris), contact)
    surface = TriangleSurface(verts, tris, name=articular.name, source=articular.source)
    notes: list[str] = []
    smoothed = 0
    dropped = 0
    worst_lean = 0.0
    keep = np.ones(len(tris), bool)
    zero_mm = ZERO_THICKNESS_FRACTION * float(np.ptp(verts, axis=0).max())
    while True:
        verts, tris, tri_index = submesh(surface, keep)
        normals = smooth_directions(verts, tris)
        thickness = np.asarray(thickness_at(verts, -normals), float)
        if not (np.isfinite(thickness).all() and (thickness >= 0).all()):
            raise ValueError("measured_layer_solid: a vertex has no finite thickness >= 0")
        # the margin where a tapered layer meets its bone: a column of no height (extrude collapses it to a point)
        thickness[thickness <= zero_mm] = 0.0
        if not thickness.any():
            raise ValueError("measured_layer_solid: the layer has no thickness anywhere")
        n_layers = layers_for(layers_through_thickness, float(thickness.max()), size)
        thickness, normals, bad, touched = _smooth_inverted(verts, tris, normals, thickness, n_layers)
        if not bad.any():
            smoothed = int(touched.sum())
            break
        rim = bad & rim_triangles(tris)
        if not rim.any():
            raise ValueError(
                f"measured_layer_solid: {int(bad.sum())} prisms inside the surface still turn inside out after smoothing "
                f"the thickness: remesh the articular surface there (near {np.round(verts[tris[bad][0]].mean(axis=0), 2).tolist()} mm)")
        a, b, c = (verts[tris[:, k]] for k in range(3))
        own = np.cross(b - a, c - a)
        own /= np.linalg.norm(own, axis=1)[:, None]
        cos = np.min(np.einsum("ikj,ij->ik", normals[tris], own), axis=1)
        worst_lean = max(worst_lean, float(np.degrees(np.arccos(np.clip(cos[rim], -1, 1))).max()))
        dropped += int(rim.sum())
        keep[tri_index[rim]] = False
        if not keep.any():
            raise ValueError("measured_layer_solid: every prism turns inside out")
    if smoothed:
        notes.append(f"cartilage solid: the measured thickness and the extrusion directions were smoothed under {smoothed} "
                     "triangles whose prisms would turn inside out (a thickness step or a sliver's leaning normal)")
    if dropped:
        notes.append(f"cartilage solid: {dropped} rim triangles dropped (vertex normals leaning up to {worst_lean:.0f} deg "
                     "from their own: their prisms turn inside out)")
    solid = extrude("measured-layer", verts - thickness[:, None] * normals, tris, normals, thickness, n_layers)
    return solid, notes


def opposing_layer_solid(
    mobile: FESolid,
    facing_points_mm: np.ndarray,
    thickness_at: Callable[[np.ndarray, np.ndarray], np.ndarray],
    layers_through_thickness: int | None = None,
) -> tuple[FESolid, list[str]]:
    """F's cartilage built on M's contact face, paired with it point to point, in one solid with
    M's (docs/method.md#two-deformable-layers).

    Parameters
    ----------
    mobile : FESolid
        M's layer (its contact face, CONTACT_TAG, faces F).
    facing_points_mm : (n_points, 3) float
        Per point of ``mobile``: where the ray from its contact-face point along its column meets
        F's articular surface (NaN where it does not, and off the contact face).
    thickness_at : callable
        ``thickness_at(vertices (k, 3) mm, inward unit directions (k, 3)) -> (k,) mm``: F's
        cartilage thickness below its articular surface (as :func:`measured_layer_solid`).
    layers_through_thickness : int, optional
        F's element layers (default: its largest thickness over the mean edge).

    Returns
    -------
    solid : FESolid
        :func:`geometries.fe_solids.pair_solids` of M's layer and F's: F's articular face is M's
        contact triangulation (every triangle whose three rays meet F) carried onto F, so both
        contact faces have the same connectivity; F's columns go down its smoothed normals to its
        bone (:func:`measured_layer_solid`, whose repairs may drop a few rim triangles).
    notes : list of str
        The construction's notes (M's contact triangles left without a partner, F's repairs).
    """
    from scipy.spatial import cKDTree

    from geometries.fe_solids import CONTACT_TAG, pair_solids

    contact = mobile.faces(CONTACT_TAG)
    facing = np.asarray(facing_points_mm, float)
    hit = np.all(np.isfinite(facing[contact]), axis=(1, 2))
    notes: list[str] = []
    if not hit.any():
        raise ValueError("opposing_layer_solid: no ray from M's contact face meets F's articular surface")
    used = np.unique(contact[hit])
    remap = np.full(len(mobile.points_mm), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    # M's contact triangles are oriented out of M, towards F: reversed, they face out of F
    articular = TriangleSurface(facing[used], remap[contact[hit]][:, ::-1].copy(), name="fixed-articular")
    fixed, fixed_notes = measured_layer_solid(articular, np.ones(int(hit.sum()), bool), thickness_at, None, layers_through_thickness)
    notes += [note.replace("cartilage solid", "fixed cartilage solid") for note in fixed_notes]
    top = np.flatnonzero(fixed.layer == fixed.layer.max())
    dist, nearest = cKDTree(fixed.points_mm[top]).query(facing[used])
    found = dist <= 1e-9 * max(float(np.ptp(fixed.points_mm, axis=0).max()), 1.0)
    partner = np.full(len(mobile.points_mm), -1, dtype=np.int64)
    partner[used[found]] = top[nearest[found]]
    solid = pair_solids(mobile, fixed, partner, name="two-layer")
    unpaired = len(contact) - int(np.sum(solid.facet_tags == CONTACT_TAG))
    if unpaired:
        notes.append(f"two-layer solid: {unpaired} of M's {len(contact)} contact triangles face no cartilage of F "
                     "(their rays miss F's articular surface, or F's rim was trimmed): free faces")
    return solid, notes
