"""Triangulated bone surfaces: the shared geometry type of the discrete solver (SPEC 2)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


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
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

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
            self._cache["area_vectors"] = 0.5 * np.cross(b - a, c - a)
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
