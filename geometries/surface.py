"""Triangulated bone surfaces: the shared geometry type of the discrete solver (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geometries.triangle_kernels import triangle_area_vectors


@dataclass(frozen=True)
class TriangleSurface:
    """A triangulated surface in mm with consistently oriented triangles.

    For the mobile body the triangle normals (right-hand rule on ``triangles``) point out of the
    bone towards the opposing body; for the fixed body they point out of it towards the mobile one.
    """

    vertices_mm: np.ndarray  # (n_vertices, 3) float64
    triangles: np.ndarray  # (n_triangles, 3) int64
    name: str = ""
    source: str = ""  # file it was read from, for error messages
    # Derived arrays, computed on first use. Not an init field, so dataclasses.replace (new
    # vertices, say) starts with an empty cache instead of sharing stale centroids and normals.
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])

    def _corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        v = self.vertices_mm
        t = self.triangles
        return v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]

    @property
    def centroids_mm(self) -> np.ndarray:
        if "centroids" not in self._cache:
            a, b, c = self._corners()
            self._cache["centroids"] = (a + b + c) / 3.0
        return self._cache["centroids"]

    @property
    def area_vectors_mm2(self) -> np.ndarray:
        """Half the cross product of two edges: area times unit normal, per triangle."""
        if "area_vectors" not in self._cache:
            a, b, c = self._corners()
            self._cache["area_vectors"] = triangle_area_vectors(a, b, c)
        return self._cache["area_vectors"]

    @property
    def areas_mm2(self) -> np.ndarray:
        return np.linalg.norm(self.area_vectors_mm2, axis=1)

    @property
    def unit_normals(self) -> np.ndarray:
        """Unit normals; zero rows for degenerate (zero-area) triangles."""
        av = self.area_vectors_mm2
        area = np.linalg.norm(av, axis=1)
        out = np.zeros_like(av)
        ok = area > 0
        out[ok] = av[ok] / area[ok, None]
        return out


def midpoint_subdivision(triangles: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """One 1 -> 4 midpoint subdivision of a triangulation, orientation kept.

    Returns the new triangles and the (n_edges, 2) vertex pairs of the unique edges: the caller
    appends one new vertex per edge, in that order, after the ``n_vertices`` existing ones (the
    edge midpoint, projected or interpolated as the caller needs).
    """
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    pairs, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = inverse.reshape(3, -1).T + n_vertices
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    children = np.stack(
        [np.column_stack([a, ab, ca]), np.column_stack([ab, b, bc]), np.column_stack([ca, bc, c]), np.column_stack([ab, bc, ca])],
        axis=1,
    )
    return children.reshape(-1, 3), pairs
