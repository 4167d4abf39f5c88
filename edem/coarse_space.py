"""The coupled layer's coarse smoothing space (``[cartilage] thin_layer_smoothing_resolution``).

The layer's smoothed field (``edem.thin_layer``) varies over sqrt(b) h (about 2.5 mm for the
Pade on a 2 mm layer) while springs may be 0.3 mm apart, so with ``smoothing_resolution`` r > 0
a term whose coarse cells sqrt(b) h / r are at least COARSE_MIN_SPRINGS springs across is solved
on a subspace of the P1 space: v = P v_c, P (v, V_c) the interpolation of a coarse triangulation
(``coarse_transfer``), with the Galerkin operators H_c = P^T H P and Z_c = P^T Z, so

    C_c = diag(c_loc / A) + sigma Z_c^T H_c^-1 Z_c.

It is symmetric; P H_c^-1 P^T <= H^-1 (an H-orthogonal projection), so for sigma = -1 the
coarse term removes less than the fine one: C_c >= C (still positive definite), converging to
it as P -> I (P = I once every vertex is a coarse one). The coarse functions sum to one where
none was dropped, so a uniform pressure on a layer without free edges still deflects it by
h p / E'; the coarse vertices on the free edge are dropped, so the field still vanishes there.
The coupled matrix keeps its form, sigma H_c + Z_c diag(x) Z_c^T, on the coarse pattern.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from edem.sparse_factors import OperatorPattern, concatenated_ranges


#: A term is solved on a coarse space only where its coarse size is at least this many springs
#: across (the side sqrt(2 A) of the median triangle): below, the space keeps most of the
#: vertices (1 mm cubes kept 0.74 of them on 0.94 mm springs) and building it costs more than
#: the smaller factor saves (benchmarks/bench_coarse_smoothing.py).
COARSE_MIN_SPRINGS = 2.0


def _cube_seeds(points_mm: np.ndarray, size_mm: float) -> np.ndarray:
    """Indices into ``points_mm`` (k, 3): per cube of side ``size_mm`` that holds any, the point
    nearest the mean of those it holds."""
    if points_mm.shape[0] == 0:
        return np.zeros(0, np.int64)
    cube = np.floor((points_mm - points_mm.min(axis=0)) / size_mm).astype(np.int64)
    span = cube.max(axis=0) + 1
    _, group = np.unique((cube[:, 0] * span[1] + cube[:, 1]) * span[2] + cube[:, 2], return_inverse=True)
    count = np.bincount(group)
    centre = np.column_stack([np.bincount(group, weights=points_mm[:, k]) for k in range(3)]) / count[:, None]
    order = np.lexsort((np.linalg.norm(points_mm - centre[group], axis=1), group))  # per cube, nearest first
    return order[np.r_[True, group[order][1:] != group[order][:-1]]]


def coarse_transfer(vertices_mm: np.ndarray, triangles: np.ndarray, kept: np.ndarray, fixed: np.ndarray, size_mm: float) -> sp.csr_matrix:
    """P (kept.size, V_c): the values at the fine vertices ``kept`` of the P1 functions of a coarse
    triangulation, about ``size_mm`` across, of the surface ``triangles`` (m, 3) (module docstring).

    Coarse vertices: one fine vertex per cube of side ``size_mm`` among ``kept``, and among
    ``fixed`` (the vertices where the field vanishes), whose functions are then dropped. Each fine
    vertex belongs to its nearest coarse vertex along the mesh's edges (scipy's multi-source
    Dijkstra); a fine triangle whose corners belong to three coarse vertices makes a coarse
    triangle (the dual of those regions). A fine vertex takes its barycentric coordinates in the
    coarse triangle around its own coarse vertex that holds it best (its projection on the
    triangle's plane; negative coordinates clipped, the rest rescaled to sum 1), so P 1 = 1 where
    no function was dropped, and linear fields are kept inside the coarse triangles. A coarse
    vertex is itself a fine vertex with its identity row, so P has full column rank.
    """
    tri = np.asarray(triangles, np.int64)
    n = vertices_mm.shape[0]
    inner = kept[_cube_seeds(vertices_mm[kept], size_mm)]
    seeds = np.concatenate([inner, fixed[_cube_seeds(vertices_mm[fixed], size_mm)]])
    key = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1) @ np.array([n, 1]))
    a, b = key // n, key % n
    # + 1e-300: an edge of zero length (coincident vertices) would read as no edge
    graph = sp.csr_matrix((np.linalg.norm(vertices_mm[a] - vertices_mm[b], axis=1) + 1e-300, (a, b)), shape=(n, n))
    _, _, source = dijkstra(graph, directed=False, indices=seeds, return_predecessors=True, min_only=True)
    seed_index = np.full(n, -1)
    seed_index[seeds] = np.arange(seeds.size)
    region = np.where(source >= 0, seed_index[np.maximum(source, 0)], -1)  # (n,) the nearest coarse vertex
    corners = region[tri]
    dual = np.all(corners >= 0, axis=1) & (corners[:, 0] != corners[:, 1]) & (corners[:, 1] != corners[:, 2]) & (corners[:, 0] != corners[:, 2])
    coarse = np.unique(np.sort(corners[dual], axis=1), axis=0)  # (k, 3) coarse triangles, in seed indices
    # Every (fine vertex, coarse triangle around its coarse vertex) pair.
    own = region[kept]
    around = sp.csr_matrix((np.ones(coarse.size), (coarse.ravel(), np.repeat(np.arange(coarse.shape[0]), 3))), shape=(seeds.size, coarse.shape[0]))
    count = np.where(own >= 0, np.diff(around.indptr)[np.maximum(own, 0)], 0)
    vertex = np.repeat(np.arange(kept.size), count)
    triangle = around.indices[concatenated_ranges(around.indptr[np.maximum(own, 0)], count)]
    corner = vertices_mm[seeds[coarse[triangle]]]  # (pairs, 3, 3)
    e1, e2, d = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0], vertices_mm[kept[vertex]] - corner[:, 0]
    g11, g12, g22 = np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e1, e2), np.einsum("ij,ij->i", e2, e2)
    r1, r2 = np.einsum("ij,ij->i", e1, d), np.einsum("ij,ij->i", e2, d)
    det = g11 * g22 - g12 * g12
    flat = det > 1e-12 * g11 * g22  # not a degenerate coarse triangle
    det = np.where(flat, det, 1.0)
    beta, gamma = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    bary = np.column_stack([1.0 - beta - gamma, beta, gamma])
    score = np.where(flat, bary.min(axis=1), -np.inf)
    order = np.lexsort((-score, vertex))
    best = order[np.r_[True, vertex[order][1:] != vertex[order][:-1]]] if order.size else order
    best = best[np.isfinite(score[best])]
    weight = np.clip(bary[best], 0.0, None)
    weight /= weight.sum(axis=1, keepdims=True)
    located = np.zeros(kept.size, bool)
    located[vertex[best]] = True
    alone = np.flatnonzero(~located & (own >= 0))  # no coarse triangle around: its coarse vertex's value
    rows = np.concatenate([np.repeat(vertex[best], 3), alone])
    cols = np.concatenate([coarse[triangle[best]].ravel(), own[alone]])
    vals = np.concatenate([weight.ravel(), np.ones(alone.size)])
    keep = (cols < inner.size) & (vals > 0.0)  # the fixed vertices' functions are dropped: the field vanishes there
    p = sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(kept.size, inner.size))
    p.sum_duplicates()
    return p


@dataclass(frozen=True)
class CoarseSpace:
    """One smoothing term's coarse space on a cell set: the transfer P (v, V_c) from the coarse to
    the fine vertices and the pattern of H_c + Z_c diag(x) Z_c^T (V_c, V_c), whose Q is Q P (m, V_c).

    Z_c diag(x) Z_c^T adds x_t c_nl,t^2 (QP)_ta (QP)_tb at each pair (a, b) of spring t's coarse
    vertices: ``pair_sums`` (nnz, m) holds (QP)_ta (QP)_tb at the pair's stored entry and spring
    t's column, so the coupled matrix's data is one sparse product (``SmoothingTerm.coupled_data``;
    0.6 ms against 1.5 ms for a gather and bincount over the springs of nonzero weight on the
    30k-spring ankle's coarse space, 0.43M pairs, and the same sums to the bit: each row adds its
    springs in ascending order, as the bincount did).
    """

    transfer: sp.csr_matrix
    pattern: OperatorPattern
    keys: np.ndarray  # (nnz,) column * V_c + row of each stored entry (sorted)
    pair_sums: sp.csr_matrix  # (nnz, m)

    @staticmethod
    def build(fine: OperatorPattern, transfer: sp.csr_matrix) -> "CoarseSpace":
        qp = (fine.q @ transfer).tocsr()
        qp.sort_indices()
        support = abs(transfer)
        structure = (support.T @ fine.matrix(np.ones(fine.indices.shape[0])) @ support).tocsc()  # no cancellation: a structural pattern
        structure.sort_indices()
        n_c = transfer.shape[1]
        keys = np.repeat(np.arange(n_c), np.diff(structure.indptr)) * n_c + structure.indices
        # Spring t's coarse pairs: every (a, b) of its row of Q P, padded to the longest row.
        count = np.diff(qp.indptr)
        m, width = qp.shape[0], int(count.max(initial=0))
        row, position = np.repeat(np.arange(m), count), np.arange(qp.indices.shape[0]) - np.repeat(qp.indptr[:-1], count)
        vertex, value = np.full((m, width), -1), np.zeros((m, width))
        vertex[row, position], value[row, position] = qp.indices, qp.data
        valid = (vertex[:, :, None] >= 0) & (vertex[:, None, :] >= 0)
        a, b = np.broadcast_to(vertex[:, :, None], valid.shape)[valid], np.broadcast_to(vertex[:, None, :], valid.shape)[valid]
        pattern = OperatorPattern(structure.indices, structure.indptr, np.zeros((0, 9), np.int64), qp, fine.whole_surface)
        # valid is row-major, spring by spring: spring t's column, each pair at a distinct entry;
        # the conversion to rows (a counting transpose, no sort) keeps every row's springs ascending
        start = np.zeros(m + 1, np.int64)
        np.cumsum(count * count, out=start[1:])
        by_spring = sp.csc_matrix(((value[:, :, None] * value[:, None, :])[valid], np.searchsorted(keys, b * n_c + a), start), shape=(keys.shape[0], m))
        return CoarseSpace(transfer, pattern, keys, by_spring.tocsr())

    def operator(self, fine_h: sp.csc_matrix) -> sp.csc_matrix:
        """H_c = P^T H P (V_c, V_c) on the coupled pattern."""
        product = (self.transfer.T @ fine_h @ self.transfer).tocoo()
        n_c = self.transfer.shape[1]
        data = np.zeros(self.keys.shape[0])
        np.add.at(data, np.searchsorted(self.keys, product.col * n_c + product.row), product.data)
        return self.pattern.matrix(data)
