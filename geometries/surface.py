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

    Returns the new triangles (child k of triangle i is row 4 i + k) and the (n_edges, 2) vertex
    pairs of the unique edges, sorted: the caller appends one new vertex per edge, in that order,
    after the ``n_vertices`` existing ones (the edge midpoint, projected or interpolated as the
    caller needs). Every triangle marked in :func:`red_green_subdivision`.
    """
    children, pairs, _, _ = red_green_subdivision(triangles, n_vertices, np.ones(len(triangles), bool))
    return children, pairs


def red_green_subdivision(
    triangles: np.ndarray, n_vertices: int, marked: np.ndarray, green: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One conforming local refinement: the ``marked`` triangles split 1 -> 4, orientation kept.

    Red-green closure: a triangle with two or three split edges is split 1 -> 4 as well (red),
    and so is a ``green`` one (born of a bisection in an earlier pass) with any split edge, so that
    no triangle is bisected twice; the triangles left with one split edge are bisected from it to
    the opposite corner (green). Every edge is then split on both of its sides or on neither: no
    hanging vertex. (A green triangle split 1 -> 4 passes its shape on: repeated passes keep the
    angles when each pass marks triangles well inside the last one's, as
    :func:`geometries.fe_solids.refine` does.)

    Parameters
    ----------
    triangles : (n, 3) int
    n_vertices : int
        Vertices of the input; the new ones are appended after them, one per split edge.
    marked : (n,) bool
        The triangles to split.
    green : (n,) bool, optional
        The triangles born of a bisection (default: none).

    Returns
    -------
    children : (k, 3) int
        The new triangulation.
    pairs : (e, 2) int
        The vertex pairs of the split edges: vertex ``n_vertices + i`` is the midpoint of pair i.
    parent : (k,) int
        The input triangle each child lies in.
    child_green : (k,) bool
        The children born of a bisection (the next pass's ``green``).
    """
    tri = np.asarray(triangles, np.int64)
    n = tri.shape[0]
    green = np.zeros(n, bool) if green is None else np.asarray(green, bool)
    sides = np.sort(np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1), axis=2)  # side j: corners j, j+1
    key, side_edge = np.unique(sides[..., 0] * n_vertices + sides[..., 1], return_inverse=True)
    side_edge = side_edge.reshape(n, 3)
    red = np.asarray(marked, bool).copy()
    while True:  # the closure spreads by at least one triangle per round, so it ends
        split = np.zeros(key.shape[0], bool)
        split[side_edge[red]] = True
        count = split[side_edge].sum(axis=1)
        closed = red | (count >= 2) | (green & (count >= 1))
        if np.array_equal(closed, red):
            break
        red = closed
    split_edges = np.flatnonzero(split)
    midpoint = np.full(key.shape[0], -1, np.int64)
    midpoint[split_edges] = n_vertices + np.arange(split_edges.size)
    pairs = np.column_stack([key[split_edges] // n_vertices, key[split_edges] % n_vertices])

    mid = midpoint[side_edge]  # (n, 3): the midpoint of side j, or -1
    a, b, c = tri[red, 0], tri[red, 1], tri[red, 2]
    ab, bc, ca = mid[red, 0], mid[red, 1], mid[red, 2]
    red_children = np.stack([np.column_stack([a, ab, ca]), np.column_stack([ab, b, bc]), np.column_stack([ca, bc, c]),
                             np.column_stack([ab, bc, ca])], axis=1).reshape(-1, 3)
    bisected = np.flatnonzero(~red & (count == 1))
    j = np.argmax(mid[bisected] >= 0, axis=1)  # the split side: corners j, j+1, opposite j+2
    corner = [tri[bisected, (j + i) % 3] for i in range(3)]
    m = mid[bisected, j]
    green_children = np.stack([np.column_stack([corner[0], m, corner[2]]), np.column_stack([m, corner[1], corner[2]])],
                              axis=1).reshape(-1, 3)
    kept = np.flatnonzero(~red & (count == 0))
    children = np.concatenate([tri[kept], red_children, green_children])
    parent = np.concatenate([kept, np.repeat(np.flatnonzero(red), 4), np.repeat(bisected, 2)])
    child_green = np.concatenate([green[kept], np.zeros(red_children.shape[0], bool), np.ones(green_children.shape[0], bool)])
    return children, pairs, parent, child_green
