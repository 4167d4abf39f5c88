"""The measured cartilage solid (geometries.cartilage_solids): the solid between an articular
surface and its bone, built down the vertex normals by each vertex's thickness.

Invariants: its contact face is the articular surface itself, its columns are as long as the
thickness asked for (a curved cap over an eccentric bone sphere: the exact ray distance), every
tetrahedron has a positive volume, and a thickness spike that would turn prisms inside out is
repaired (smoothed, said in the notes), not refused.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometries.cartilage_solids import measured_layer_solid, offset_surface
from geometries.fe_solids import CONTACT_TAG, tet_volumes, vertex_normals
from geometries.surface import TriangleSurface
from support import grid_plate

CAP_RADIUS_MM = 20.0


def cap(radius_mm: float = CAP_RADIUS_MM, half_width_mm: float = 8.0, n: int = 12) -> TriangleSurface:
    """A spherical cap over a square grid (normals out of the sphere, up +z), top at z = 0."""
    plate = grid_plate(2 * half_width_mm, 2 * half_width_mm, n)
    x, y = plate.vertices_mm[:, 0], plate.vertices_mm[:, 1]
    z = np.sqrt(radius_mm**2 - x**2 - y**2) - radius_mm
    return TriangleSurface(np.column_stack([x, y, z]), plate.triangles)


def ray_to_sphere(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Distance from each origin along its unit direction to the sphere (the far root: the origins
    lie outside a bone sphere that sits inside the cap)."""
    oc = origin - centre
    b = np.einsum("ij,ij->i", oc, direction)
    c = np.einsum("ij,ij->i", oc, oc) - radius**2
    return -b - np.sqrt(b * b - c)


def test_curved_cap_columns_are_the_ray_distance_to_an_eccentric_bone_sphere():
    # bone: a sphere of radius 18 mm centred 1 mm off the cap's centre -> thickness 1.6-2.4 mm
    articular = cap()
    centre = np.array([1.0, 0.0, -CAP_RADIUS_MM])

    def thickness_at(vertices, inward):
        return ray_to_sphere(vertices, inward, centre, 18.0)

    solid, notes = measured_layer_solid(articular, np.ones(articular.n_triangles, bool), thickness_at, None, 3)
    assert notes == []
    nv = len(articular.vertices_mm)
    top, bottom = solid.points_mm[3 * nv:], solid.points_mm[:nv]
    # the contact face is the articular surface (same vertices, to round-off)
    np.testing.assert_allclose(top, articular.vertices_mm, atol=1e-12)
    assert set(np.unique(solid.faces(CONTACT_TAG))) == set(range(3 * nv, 4 * nv))
    # each column ends on the bone sphere, as long as the ray down its direction (1e-9 mm: round-off),
    # and its direction is within a few degrees of the vertex normal (smoothed over 1 mm)
    column = top - bottom
    length = np.linalg.norm(column, axis=1)
    direction = column / length[:, None]
    expected = ray_to_sphere(articular.vertices_mm, -direction, centre, 18.0)
    np.testing.assert_allclose(length, expected, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(bottom - centre, axis=1), 18.0, atol=1e-9)
    normals = vertex_normals(articular.vertices_mm, articular.triangles)
    # the cap's normals turn by 1.9 deg per 0.67 mm edge: smoothing over 1 mm moves them by less than 5 deg
    assert np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", direction, normals), -1, 1))).max() < 5.0
    assert expected.max() - expected.min() > 0.5  # the thickness does vary
    assert np.all(tet_volumes(solid.points_mm, solid.tets) > 0)


def test_a_thickness_spike_that_inverts_prisms_is_smoothed_not_refused():
    # 1 mm everywhere but one interior vertex at 30 mm, past the cap's 20 mm radius: its column
    # would cross its neighbours' (inverted prisms); the repair averages it with its ring
    articular = cap()
    spike = int(np.argmin(np.linalg.norm(articular.vertices_mm[:, :2], axis=1)))  # the apex

    def thickness_at(vertices, inward):
        t = np.ones(len(vertices))
        t[np.argmin(np.linalg.norm(vertices[:, :2], axis=1))] = 30.0
        return t

    solid, notes = measured_layer_solid(articular, np.ones(articular.n_triangles, bool), thickness_at, None, 1)
    assert any("smoothed" in note for note in notes), notes
    assert np.all(tet_volumes(solid.points_mm, solid.tets) > 0)
    nv = len(articular.vertices_mm)
    column = np.linalg.norm(solid.points_mm[nv:] - solid.points_mm[:nv], axis=1)
    assert column[spike] < CAP_RADIUS_MM  # no longer through the centre of curvature
    far = np.linalg.norm(articular.vertices_mm[:, :2], axis=1) > 4.0  # beyond the smoothed rings: untouched
    np.testing.assert_allclose(column[far], 1.0, atol=1e-12)


def test_a_layer_tapered_to_zero_on_its_bone_follows_the_taper_down_to_a_point():
    # 1.3 mm in the middle, sin^2-tapered to 0 over 3 mm at the cap's square margin (as the built-in
    # ankles' layers): the margin's columns have no height, so each is one point on both the bonded
    # and the contact face; every column is exactly the thickness asked for (no smoothing), every
    # tetrahedron has a positive volume
    from geometries.fe_solids import BONDED_TAG, FREE_TAG

    articular = cap()
    half = 8.0

    def thickness_at(vertices, inward):
        inside = half - np.abs(vertices[:, :2]).max(axis=1)  # distance inside the margin (the square's)
        return 1.3 * np.sin(0.5 * np.pi * np.clip(inside / 3.0, 0.0, 1.0)) ** 2

    solid, notes = measured_layer_solid(articular, np.ones(articular.n_triangles, bool), thickness_at, None, 2)
    assert notes == []
    assert np.all(tet_volumes(solid.points_mm, solid.tets) > 0)
    # the contact face is the articular surface but for the triangles with every corner on the margin
    # (no cartilage at all: two at the grid's corners)
    on_margin = np.isclose(np.abs(articular.vertices_mm[:, :2]).max(axis=1), half, atol=1e-12)
    kept = ~on_margin[articular.triangles].all(axis=1)
    assert len(solid.faces(CONTACT_TAG)) == int(kept.sum()) == articular.n_triangles - 2
    top = np.unique(solid.faces(CONTACT_TAG))
    np.testing.assert_allclose(np.sort(solid.points_mm[top], axis=0), np.sort(articular.vertices_mm[np.unique(articular.triangles[kept])], axis=0), atol=1e-12)
    column = solid.points_mm[top] - solid.points_mm[solid.bottom_vertex[top]]
    height = np.linalg.norm(column, axis=1)
    margin = np.isclose(np.abs(solid.points_mm[top, :2]).max(axis=1), half, atol=1e-12)
    assert margin.sum() == 4 * 12 - 2 and np.all(height[margin] == 0.0)
    tall = ~margin
    np.testing.assert_allclose(height[tall], thickness_at(solid.points_mm[top[tall]], -column[tall] / height[tall, None]), atol=1e-12)
    # the margin's points are corners of the bonded face too, and no free face is left at the margin
    assert set(top[margin]) <= set(np.unique(solid.faces(BONDED_TAG)))
    assert not np.any(solid.facet_tags == FREE_TAG)


def test_offset_surface_moves_every_vertex_by_the_distance_along_its_normal():
    # a sphere cap offset by 2 mm is the concentric cap of radius R + 2: inside the rim the vertex
    # normals are radial up to the faceting (1e-3 mm for 1.3 mm edges on R 20 mm; the rim's are one-sided)
    articular = cap()
    moved = offset_surface(articular, 2.0)
    centre = np.array([0.0, 0.0, -CAP_RADIUS_MM])
    inside = np.abs(articular.vertices_mm[:, :2]).max(axis=1) < 8.0 - 1e-9
    np.testing.assert_allclose(np.linalg.norm(moved.vertices_mm[inside] - centre, axis=1), CAP_RADIUS_MM + 2.0, atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(moved.vertices_mm - articular.vertices_mm, axis=1), 2.0, atol=1e-12)


def test_opposing_layer_is_built_on_the_mobile_contact_face_and_paired_point_to_point():
    """F's layer under a curved M layer: its articular face is M's contact triangulation carried
    along M's columns onto the plane z = 1 (the points given), its columns reach F's bone 0.8 mm
    beyond (the thickness asked for, along F's normal +z: exactly, F's face being flat), every
    paired point of M faces its partner, and a triangle whose ray misses F becomes a free face."""
    from geometries.cartilage_solids import opposing_layer_solid
    from geometries.fe_solids import FIXED_CONTACT_TAG, FIXED_VOLUME_TAG, FREE_TAG

    surface = cap()
    mobile, _ = measured_layer_solid(TriangleSurface(surface.vertices_mm, surface.triangles), np.ones(surface.n_triangles, bool),
                                     lambda v, d: np.full(len(v), 1.0), None, 2)
    top = np.unique(mobile.faces(CONTACT_TAG))
    column = mobile.points_mm[top] - mobile.points_mm[mobile.bottom_vertex[top]]
    column /= np.linalg.norm(column, axis=1)[:, None]
    facing = np.full_like(mobile.points_mm, np.nan)
    s = (1.0 - mobile.points_mm[top, 2]) / column[:, 2]  # rays onto z = 1
    facing[top] = mobile.points_mm[top] + s[:, None] * column
    facing[top[np.argmax(np.hypot(mobile.points_mm[top, 0], mobile.points_mm[top, 1]))]] = np.nan  # a corner's ray misses
    solid, notes = opposing_layer_solid(mobile, facing, lambda v, d: np.full(len(v), 0.8), 2)
    assert np.all(tet_volumes(solid.points_mm, solid.tets) > 0)
    paired = np.unique(solid.faces(CONTACT_TAG))
    np.testing.assert_allclose(solid.points_mm[solid.partner[paired]], facing[paired], atol=1e-12)
    assert np.all(solid.partner[solid.partner[paired]] == paired)
    fixed_face = np.unique(solid.faces(FIXED_CONTACT_TAG))
    np.testing.assert_allclose(solid.points_mm[fixed_face, 2], 1.0, atol=1e-12)
    bottom = solid.bottom_vertex[fixed_face]
    np.testing.assert_allclose(solid.points_mm[bottom] - solid.points_mm[fixed_face], [[0.0, 0.0, 0.8]] * len(bottom), atol=1e-9)
    assert int(np.sum(solid.cell_tags == FIXED_VOLUME_TAG)) > 0
    # the corner's triangles are left to M as free faces, said in the notes
    assert len(solid.faces(CONTACT_TAG)) < len(mobile.faces(CONTACT_TAG))
    assert np.sum(solid.facet_tags == FREE_TAG) > np.sum(mobile.facet_tags == FREE_TAG)
    assert any("face no cartilage of F" in note for note in notes)


def test_pairing_solids_refuses_faces_with_no_triangle_in_common():
    """pair_solids keeps a contact triangle only when its partners form one of F's: none -> ValueError."""
    import pytest

    from geometries.fe_solids import extrude, pair_solids

    plate = grid_plate(4.0, 4.0, 2)
    n = len(plate.vertices_mm)
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    mobile = extrude("m", plate.vertices_mm + [0.0, 0.0, 2.0], plate.triangles[:, ::-1], -up, np.full(n, 1.0), 1)
    fixed = extrude("f", plate.vertices_mm - [0.0, 0.0, 1.0], plate.triangles, up, np.full(n, 1.0), 1)
    partner = np.full(len(mobile.points_mm), -1)
    partner[n:] = n  # every point paired with one point of F: no triangle in common
    with pytest.raises(ValueError, match="no contact triangle"):
        pair_solids(mobile, fixed, partner)
    partner[n:] = n + np.arange(n)
    assert len(pair_solids(mobile, fixed, partner).faces(CONTACT_TAG)) == len(plate.triangles)
