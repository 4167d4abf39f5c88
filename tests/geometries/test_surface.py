"""TriangleSurface: derived arrays follow the vertices, also through dataclasses.replace."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from geometries.surface import TriangleSurface

TRIANGLE = TriangleSurface(np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 3.0, 0.0]]), np.array([[0, 1, 2]]))


def test_replace_with_moved_vertices_recomputes_centroids_areas_and_normals():
    assert np.allclose(TRIANGLE.centroids_mm, [[1.0, 1.0, 0.0]])  # fills the cache
    assert np.allclose(TRIANGLE.unit_normals, [[0.0, 0.0, 1.0]])
    moved = dataclasses.replace(TRIANGLE, vertices_mm=2.0 * TRIANGLE.vertices_mm[:, [2, 0, 1]])
    # the moved triangle: (0,0,0), (0,6,0), (0,0,6): centroid (0, 2, 2), area 18, normal +x
    assert np.allclose(moved.centroids_mm, [[0.0, 2.0, 2.0]])
    assert np.allclose(moved.areas_mm2, [18.0])
    assert np.allclose(moved.unit_normals, [[1.0, 0.0, 0.0]])
    assert np.allclose(TRIANGLE.centroids_mm, [[1.0, 1.0, 0.0]])  # the original keeps its own


def _grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """An n x n square of 1 mm cells, two counter-clockwise triangles each."""
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    corner = np.arange((n + 1) * (n + 1)).reshape(n + 1, n + 1)[:-1, :-1].ravel()
    triangles = np.concatenate([np.column_stack([corner, corner + 1, corner + n + 2]),
                                np.column_stack([corner, corner + n + 2, corner + n + 1])])
    return vertices, triangles


def _edge_counts(triangles: np.ndarray) -> np.ndarray:
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0, return_counts=True)[1]


def _smallest_angle_deg(vertices: np.ndarray, triangles: np.ndarray) -> float:
    corners = vertices[triangles]
    angles = []
    for i in range(3):
        u = corners[:, (i + 1) % 3] - corners[:, i]
        v = corners[:, (i + 2) % 3] - corners[:, i]
        cos = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return float(np.min(angles))


def test_red_green_refinement_is_conforming_keeps_area_and_orientation_and_never_bisects_twice():
    """Three local passes around a disc (geometries.fe_solids.refine with a ContactRefinement):
    every edge is shared by two triangles or lies on the square's boundary, whose 4n edges stay
    whole (no hanging vertex), the area is the square's to round-off, every triangle keeps its
    counter-clockwise orientation, the triangles in the disc have the asked size and, since no
    triangle is bisected twice, the smallest angle is one bisection's of a grid triangle."""
    from geometries.fe_solids import ContactRefinement, refine
    from geometries.triangle_kernels import triangle_areas

    n = 16  # the disc's passes grow it by at most 4 x 1 + 2 x 0.5 mm: off the boundary
    vertices, triangles = _grid(n)
    # the grid's mean edge is (2 + sqrt 2) / 3 = 1.14 mm: three halvings to 0.15 mm give legs of 0.125 mm
    near = ContactRefinement(0.15, lambda p: np.hypot(p[:, 0] - 8.0, p[:, 1] - 8.0) < 1.5)
    fine_vertices, fine_triangles, _ = refine(vertices, triangles, [], 0, near)
    area = triangle_areas(*(fine_vertices[fine_triangles[:, i]] for i in range(3)))
    assert area.sum() == pytest.approx(n * n, rel=1e-13)
    corners = fine_vertices[fine_triangles]
    cross_z = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2]
    assert np.all(cross_z > 0.0)
    counts = _edge_counts(fine_triangles)
    on_boundary = np.count_nonzero(counts == 1)
    assert set(np.unique(counts)) <= {1, 2} and on_boundary == 4 * n  # the disc stays off the boundary
    # one bisection of a grid triangle from a leg's midpoint leaves arctan(1/3) = 18.4 deg; a
    # second bisection of such a half would leave 8.1 deg
    assert _smallest_angle_deg(fine_vertices, fine_triangles) >= np.degrees(np.arctan(1.0 / 3.0)) - 1e-9
    centre = np.hypot(corners[..., 0].mean(axis=1) - 8.0, corners[..., 1].mean(axis=1) - 8.0) < 1.5
    legs = np.linalg.norm(corners[centre] - np.roll(corners[centre], 1, axis=1), axis=2)
    assert legs.min() == pytest.approx(0.125) and legs.max() == pytest.approx(0.125 * np.sqrt(2.0))


def test_red_green_closure_splits_a_green_triangle_instead_of_bisecting_it_again():
    """Two triangles sharing the diagonal, the first marked: it splits 1 -> 4 and the second is
    bisected (two green halves). A second pass marking the four red children splits the diagonal's
    halves: each green half has a split edge and is split 1 -> 4, never bisected again, and the
    counts follow by hand (16 + 8 triangles, 5 + 4 new vertices)."""
    from geometries.surface import red_green_subdivision

    _, triangles = _grid(1)
    children, pairs, parent, green = red_green_subdivision(triangles, 4, np.array([True, False]))
    assert children.shape[0] == 6 and pairs.shape[0] == 3 and green.sum() == 2
    assert np.array_equal(np.sort(parent), [0, 0, 0, 0, 1, 1])
    again, pairs_again, _, green_again = red_green_subdivision(children, 7, ~green, green)
    assert set(np.unique(_edge_counts(again))) <= {1, 2}
    # the red children's 9 distinct sides and the green halves' 3 others (the bisecting line, two boundary halves)
    assert again.shape[0] == 24 and pairs_again.shape[0] == 12 and not green_again.any()
