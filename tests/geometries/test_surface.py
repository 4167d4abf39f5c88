"""TriangleSurface: derived arrays follow the vertices, also through dataclasses.replace."""

from __future__ import annotations

import dataclasses

import numpy as np

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
