"""geometries/triangle_kernels.py: the one cross product and the one closest-point kernel."""

from __future__ import annotations

import numpy as np

from geometries.triangle_kernels import closest_points_on_triangles, cross_rows


def test_cross_rows_is_the_cross_product_row_by_row_and_against_one_vector():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(500, 3)), rng.normal(size=(500, 3))
    # the same two products and one difference per component as np.cross: equal to the bit
    np.testing.assert_array_equal(cross_rows(a, b), np.cross(a, b))
    v = np.array([0.5377, 0.8326, 0.1329])
    np.testing.assert_array_equal(cross_rows(a, v), np.cross(a, v))


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
