"""geometries/triangle_kernels.py: the one cross product, area and closest-point kernel."""

from __future__ import annotations

import numpy as np
import pytest

from geometries.triangle_kernels import closest_distance_mm, closest_points_on_triangles, cross_rows, triangle_area_vectors, triangle_areas


def test_cross_rows_is_the_cross_product_row_by_row_and_against_one_vector():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(500, 3)), rng.normal(size=(500, 3))
    # the same two products and one difference per component as np.cross: equal to the bit
    np.testing.assert_array_equal(cross_rows(a, b), np.cross(a, b))
    v = np.array([0.5377, 0.8326, 0.1329])
    np.testing.assert_array_equal(cross_rows(a, v), np.cross(a, v))


def test_triangle_areas_are_heron_s_and_the_area_vectors_follow_the_right_hand_rule():
    """Against Heron's formula from the three side lengths (a different route to the same number:
    relative 1e-12, Heron's own cancellation on these well-shaped random triangles staying below
    1e-13), 0 for a degenerate triangle, and the area vector is the area along the unit normal of
    the corners' order: swapping two corners turns it over."""
    rng = np.random.default_rng(5)
    a, b, c = rng.normal(size=(3, 200, 3))
    x, y, z = (np.linalg.norm(u, axis=1) for u in (b - c, c - a, a - b))
    s = 0.5 * (x + y + z)
    np.testing.assert_allclose(triangle_areas(a, b, c), np.sqrt(s * (s - x) * (s - y) * (s - z)), rtol=1e-12)
    assert triangle_areas(a[:1], a[:1], b[:1])[0] == 0.0
    vectors = triangle_area_vectors(a, b, c)
    np.testing.assert_allclose(np.linalg.norm(vectors, axis=1), triangle_areas(a, b, c), rtol=1e-15)
    np.testing.assert_allclose(np.einsum("ij,ij->i", vectors, b - a), 0.0, atol=1e-12)  # normal to the edges
    np.testing.assert_array_equal(triangle_area_vectors(a, c, b), -vectors)


def test_closest_point_distance_is_the_minimum_over_a_dense_sampling_of_the_triangle():
    """The exact distance is never above the sampled minimum and within the sampling step of it;
    the barycentric weights sum to one, are non-negative and rebuild a point at that distance."""
    rng = np.random.default_rng(1)
    a, b, c = rng.normal(size=(3, 3))
    pts = rng.normal(scale=2.0, size=(40, 3))
    d2, w = closest_points_on_triangles(pts, *(np.tile(x, (40, 1)) for x in (a, b, c)))
    s = np.linspace(0, 1, 301)
    S, T = np.meshgrid(s, s)
    m = (S + T) <= 1
    samples = a + np.outer(S[m], b - a) + np.outer(T[m], c - a)
    brute = ((pts[:, None, :] - samples[None]) ** 2).sum(-1).min(1)
    assert np.all(d2 <= brute + 1e-12)  # round-off of squared distances of order 1
    # a grid step of 1/300 of edges of length ~2 leaves the sampled point within ~0.02 of the exact one
    assert np.allclose(np.sqrt(d2), np.sqrt(brute), atol=0.02)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(w >= -1e-12)
    foot = w @ np.stack([a, b, c])
    np.testing.assert_allclose(((pts - foot) ** 2).sum(axis=1), d2, rtol=1e-9, atol=1e-12)


def test_closest_point_on_a_degenerate_triangle_is_on_its_segment():
    """A zero-area triangle (c on segment ab) has its closest points on the segment ab."""
    a, b = np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0])
    c = 0.5 * (a + b)
    pts = np.array([[1.0, 1.0, 0.0], [3.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    d2, _ = closest_points_on_triangles(pts, *(np.tile(x, (3, 1)) for x in (a, b, c)))
    np.testing.assert_allclose(d2, [1.0, 2.0, 1.0], rtol=1e-14)


def _brute_closest_distance_mm(a_vertices, a_triangles, b_vertices, b_triangles) -> float:
    """Every vertex of each surface against every triangle of the other."""
    def one_way(points, vertices, triangles):
        corners = vertices[triangles]
        d2, _ = closest_points_on_triangles(points[:, None, :], corners[None, :, 0], corners[None, :, 1], corners[None, :, 2])
        return float(np.sqrt(d2.min()))

    return min(one_way(a_vertices, b_vertices, b_triangles), one_way(b_vertices, a_vertices, a_triangles))


def test_closest_distance_is_the_minimum_over_every_vertex_and_triangle_both_ways():
    """The pruned search (nearest-vertex bound, centroid radius, plane and sideways distance)
    measures every pair that can hold the minimum: the same distance as all pairs, on a box of 12
    large triangles under a fine bumpy sheet (each sheet vertex has several box triangles in reach,
    few near), on two conforming bumpy sheets 2 mm apart (a joint: every vertex has many triangles'
    planes near it, few triangles) and on random triangle soups."""
    box = np.array([[x, y, z] for x in (-20.0, 20.0) for y in (-20.0, 20.0) for z in (-10.0, 0.0)])
    box_triangles = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                              [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    u, v = np.meshgrid(np.linspace(-25.0, 25.0, 31), np.linspace(-25.0, 25.0, 31))
    sheet = np.column_stack([u.ravel(), v.ravel(), 1.3 + 0.01 * (u.ravel() ** 2 + v.ravel() ** 2)])
    i = (np.arange(30)[:, None] * 31 + np.arange(30)[None]).ravel()
    sheet_triangles = np.vstack([np.column_stack([i, i + 1, i + 32]), np.column_stack([i, i + 32, i + 31])])
    rng = np.random.default_rng(5)
    bumps = sheet + rng.uniform(-0.05, 0.05, sheet.shape) + [0.3, 0.2, 2.0]
    cases = [(sheet, sheet_triangles, box, box_triangles), (sheet, sheet_triangles, bumps, sheet_triangles[:, ::-1])]
    for _ in range(10):
        a, b = rng.normal(scale=rng.uniform(0.5, 5.0), size=(40, 3)), rng.normal(scale=rng.uniform(0.5, 5.0), size=(30, 3)) + rng.normal(scale=3.0, size=3)
        cases.append((a, rng.integers(0, 40, size=(50, 3)), b, rng.integers(0, 30, size=(40, 3))))
    for case in cases:
        # the same kernel on the same pairs: equal up to the round-off of one pair's arithmetic
        assert closest_distance_mm(*case)[0] == pytest.approx(_brute_closest_distance_mm(*case), rel=1e-12)
    assert closest_distance_mm(*cases[0])[0] == pytest.approx(1.3, rel=1e-12)  # the sheet's lowest point over the box's top


def test_nearby_distance_is_zero_on_the_surface_and_the_height_above_a_plane():
    """Points on a triangulated plane (vertices, edge midpoints, inside triangles) are at 0 (round-off
    of coordinates of order 10: 1e-12), points above it at their height (the triangle below them is
    among the nearest centroids), as the closest-point kernel measures against every triangle."""
    from geometries.triangle_kernels import nearby_distance_mm
    from support import grid_plate

    plate = grid_plate(10.0, 10.0, 10)
    v, t = plate.vertices_mm, plate.triangles
    rng = np.random.default_rng(7)
    on = np.vstack([v, 0.5 * (v[t[:, 0]] + v[t[:, 1]]), v[t].mean(axis=1)])
    np.testing.assert_allclose(nearby_distance_mm(on, v, t), 0.0, atol=1e-12)
    above = np.column_stack([rng.uniform(-4.9, 4.9, (50, 2)), rng.uniform(0.1, 2.0, 50)])
    np.testing.assert_allclose(nearby_distance_mm(above, v, t), above[:, 2], rtol=1e-12)
    every = np.sqrt(closest_points_on_triangles(above[:, None, :], *(v[t][None, :, k] for k in range(3)))[0].min(axis=1))
    np.testing.assert_allclose(nearby_distance_mm(above, v, t), every, rtol=1e-12)
