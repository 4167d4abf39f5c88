"""Coupled thin-layer cartilage: a bonded elastic layer's lateral coupling as a sparse surface operator.

The layer's symbol, a rational model of its compliance C(kh) (``edem.layer_symbols``: the exact
compliance of a bonded layer, its Pade and two-pole fits), becomes here an operator on the
spring-bearing surface; its matrices are factored by ``edem.sparse_factors``, and solved on a
coarse subspace where asked (``edem.coarse_space``).

The surface operator
--------------------
As an operator, (1 - b h^2 lap) w = (h/G)(e - a h^2 lap) p. Dividing the polynomials,

    w = c_loc p + sigma c_nl S p,  S = (1 - b h^2 lap)^-1,
    c_loc = (h/G) a/b,  c_nl = (h/G) |c1| / b,  sigma = -sign(c1),

one local term and one screened-Poisson smoothing (sigma = -1 for nu > 1/4: pressing a point lifts
its neighbours, the incompressible bulge; c_loc - c_nl = (h/G) e). Where h varies,

    S = (c_nl - div(b h^2 c_nl grad))^-1 c_nl,

which keeps c_nl S symmetric, keeps S 1 = 1 (a uniform pressure deflects the layer by h p / E'
at every thickness) and gives for long waves w = (h/G) e p - (c1/G) div(h^3 grad p): the
variable-thickness thin-layer law with h^3 inside the divergence (for nu = 1/2, -(1/3G)
div(h^3 grad p)). For constant h it is the Pade exactly. (A splitting sqrt(c_nl) S sqrt(c_nl) p
would also be symmetric but deflects a uniform pressure by O(c_nl h h''), as large as the local
term e h/G at nu 0.49 on a curved joint.)

Discretisation. Spring values (pressure p, deflection w) live on the triangles (one spring per
triangle). The smoothing is solved on the vertices with P1 finite elements: the cotangent
Laplace-Beltrami stiffness K[b h^2 c_nl] (each triangle weighted by its own value) and the mass
M = Q^T diag(A c_nl) Q, where Q (Q_tv = 1/3) takes vertex values to triangle values (corner mean)
and Q^T A triangle pressures to vertex loads. With this mass, S = Q H^-1 Q^T diag(A c_nl) reduces
for K = 0 to a projection onto the range of Q, exact to O((ks)^4) on smooth fields; a lumped mass
would leave an O((ks)^2) smoothing, which the nearly incompressible layer amplifies by
c_nl / (h e / G) (93 at nu = 0.499). On forces f = A p the compliance

    w = C f,  C = diag(c_loc / A) + sigma Z^T H^-1 Z,  Z = Q^T diag(c_nl),  H = M + K,

is symmetric; it is positive definite (for sigma = -1 because Z^T H^-1 Z <= Z^T M^-1 Z, a
projection in the c_nl-weighted product, and c_loc - c_nl = (h/G) e > 0), a uniform pressure on
a layer without free edges gives the uniform deflection h p / E' (K 1 = 0, Q 1 = 1), and the
continuum symbol is recovered as the mesh size
-> 0. A cell-centred two-point Laplacian would avoid the transfer but is inconsistent on
non-orthogonal meshes (8 % anisotropy on right-triangle grids), and a transfer-based Laplacian on
cell values (Q^T K Q) has checkerboard null modes that leave nearly incompressible pressures
unresolved; here checkerboards see the finite local compliance c_loc. The intrinsic quantities
(areas, cotangents) do not change under the rigid motions of the body, so they are computed once.

Boundaries. Where the spring-bearing surface ends, the cartilage has a free lateral face: there
the smoothed field vanishes (S p = 0, Dirichlet). For e -> 0 and a plate in full contact it gives
the squeeze-film paraboloid (3 G d / 2 h^3)(a^2 - x^2) plus a uniform offset d / c_loc (the edge
pressure w / c_loc), so the edge is stiffer than the thin-layer condition p = 0; the solid lies
between the two (its free face still carries some pressure: docs/method.md, section 3). A no-flux
edge would confine the incompressible layer and make it rigid. Of the two-pole symbol's terms
(``edem.layer_symbols.two_pole_symbol``) the bulge term vanishes there, the sag term is natural. Where the contact
solve cuts the surface to a band around the candidates (``edem.thin_layer_contact``), the layer goes on, and the cut is natural.
Where the layer itself ends inside the surface (the threshold law's cartilage fills the gap only
where the springs are candidates), its edge is free like the surface's (``edge_at_cells``).

Two layers (the sandwich)
-------------------------
Two layers, each bonded to its own bone and frictionless against the other, carry the same
pressure and no shear on their faces, so they deflect independently: the sandwich's symbol is
the sum of the layers' (``edem.layer_symbols``), and so is its operator, each layer with its own
thickness field h_i: C = diag((h_1 + h_2) c_loc / (G A)) + the terms of every layer, each
sigma Z^T H^-1 Z with that layer's c_nl and b h_i^2 (``layer_compliance`` with thicknesses
(L, m)). Symmetric and positive definite as each layer's part is; a uniform pressure deflects by
(h_1 + h_2) p / E'; the long-wave term is -(c1/G) div((h_1^3 + h_2^3) grad p), where one lumped
layer of thickness h_1 + h_2 would have (h_1 + h_2)^3. A layer of zero thickness brings no term;
where it is zero on part of the surface its field is held at zero at the vertices with no
thickness around them (their rows of H and Z are empty) and its edge there is natural.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from edem.coarse_space import COARSE_MIN_SPRINGS, CoarseSpace, coarse_transfer
from edem.layer_symbols import LayerSymbol, pade_symbol
from geometries.triangle_kernels import triangle_areas
from edem.sparse_factors import (LOW_RANK_MAX, LOW_RANK_MAX_INDEFINITE, KeptOrderingLDL, LowRankUpdate, OperatorPattern, StackedPattern,
                                 indefinite_solve)


# --------------------------------------------------------------------------- surface operators


def boundary_vertices(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """(n_vertices,) bool: the vertices on an edge that only one of ``triangles`` (m, 3) has."""
    tri = np.asarray(triangles, np.int64)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    # One integer key per undirected edge: a 1-D unique is much faster than unique(axis=0).
    key, count = np.unique(edges[:, 0] * n_vertices + edges[:, 1], return_counts=True)
    single = key[count == 1]
    out = np.zeros(n_vertices, bool)
    out[single // n_vertices] = True
    out[single % n_vertices] = True
    return out


@dataclass(frozen=True)
class SurfaceMesh:
    """Intrinsic geometry of the spring-bearing surface: one spring per triangle.

    ``triangles`` index the vertices (a periodic mesh may share vertices across its seams);
    ``cotangents[t, i]`` is the cotangent of triangle t's angle at its corner i, which weights the
    opposite edge in the Laplace-Beltrami stiffness.
    """

    triangles: np.ndarray  # (n, 3) int
    area_mm2: np.ndarray  # (n,)
    cotangents: np.ndarray  # (n, 3)
    incidence: sp.csr_matrix  # (n, n_vertices) triangle-vertex incidence
    free_edge_vertex: np.ndarray  # (n_vertices,) bool: on the surface's boundary (the cartilage's free edge)
    #: (n_vertices, 3) mm, where known (``from_surface``): the coarse smoothing space needs them
    vertices_mm: np.ndarray | None = field(default=None, compare=False, repr=False)
    memo: dict = field(default_factory=dict, compare=False, repr=False)  # the operator patterns of the last cell set

    @staticmethod
    def from_corners(triangles: np.ndarray, corners_mm: np.ndarray, vertices_mm: np.ndarray | None = None) -> "SurfaceMesh":
        """From the vertex indices (n, 3) and the corner coordinates (n, 3, 3) in mm of each triangle
        (and the vertices (v, 3) in mm where there are such: a periodic mesh's corners differ
        across its seams)."""
        out = np.empty(triangles.shape)
        area = triangle_areas(corners_mm[:, 0], corners_mm[:, 1], corners_mm[:, 2])
        for i in range(3):  # the three corners of every triangle at once
            u = corners_mm[:, (i + 1) % 3] - corners_mm[:, i]
            v = corners_mm[:, (i + 2) % 3] - corners_mm[:, i]
            out[:, i] = np.einsum("ij,ij->i", u, v) / np.maximum(2.0 * area, 1e-300)
        tri = np.asarray(triangles, np.int64)
        n = tri.shape[0]
        incidence = sp.csr_matrix((np.ones(3 * n), (np.repeat(np.arange(n), 3), tri.ravel())))
        return SurfaceMesh(tri, area, out, incidence, boundary_vertices(tri, incidence.shape[1]),
                           None if vertices_mm is None else np.asarray(vertices_mm, float))

    def neighbourhood(self, cells: np.ndarray, width_mm: float, enough: int | None = None) -> np.ndarray:
        """Triangles within about ``width_mm`` of the triangles ``cells`` (bool mask, (n,)).

        Grown ring by ring through shared vertices; a ring is about one triangle size sqrt(2 A)
        wide. With ``enough``, the growth stops once the mask holds that many triangles.
        """
        incidence, incidence_t = self.incidence, self.incidence_t
        mask = np.zeros(self.triangles.shape[0], bool)
        mask[cells] = True
        size = float(np.sqrt(2.0 * self.area_mm2[mask]).mean()) if np.any(mask) else 1.0
        for _ in range(int(np.ceil(width_mm / max(size, 1e-12)))):
            if enough is not None and np.count_nonzero(mask) >= enough:
                break
            grown = incidence @ (incidence_t @ mask.astype(float)) > 0
            if np.array_equal(grown, mask):
                break
            mask = grown
        return mask

    @functools.cached_property
    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(the edge of each triangle's sides (n, 3) int, the two vertices of each edge (e, 2)),
        numbered once, so the boundary of a set of triangles is a count (``boundary_of``)."""
        tri = self.triangles
        n_vertices = self.free_edge_vertex.shape[0]
        sides = np.sort(np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1), axis=2)  # (n, 3, 2)
        key, side_edge = np.unique(sides[..., 0] * n_vertices + sides[..., 1], return_inverse=True)
        return side_edge.reshape(tri.shape), np.column_stack([key // n_vertices, key % n_vertices])

    def boundary_of(self, cells: np.ndarray) -> np.ndarray:
        """(n_vertices,) bool: the vertices on an edge that only one of the triangles ``cells`` has
        (``boundary_vertices`` of those triangles, without sorting their edges)."""
        side_edge, edge_vertices = self.edges
        count = np.bincount(side_edge[cells].ravel(), minlength=edge_vertices.shape[0])
        out = np.zeros(self.free_edge_vertex.shape[0], bool)
        out[edge_vertices[count == 1].ravel()] = True
        return out

    @functools.cached_property
    def surface_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pattern of the P1 operators on the whole surface without a free edge: the row and
        column (nnz,) of each stored entry in canonical CSC order (by column, then row) and, per
        triangle and corner pair (i, j) row-major, its entry (n, 9). Built once; every cell set's
        pattern is a restriction of it (``operator_pattern``)."""
        tri = self.triangles
        n_v = self.free_edge_vertex.shape[0]
        rows = np.repeat(tri, 3, axis=1).ravel()
        cols = np.tile(tri, (1, 3)).ravel()
        key = cols * n_v + rows  # column-major
        stored, slots = np.unique(key, return_inverse=True)
        return stored % n_v, stored // n_v, slots.reshape(tri.shape[0], 9)

    @functools.cached_property
    def incidence_t(self) -> sp.csr_matrix:
        """(n_vertices, n) the incidence transposed, for growing masks ring by ring."""
        return self.incidence.T.tocsr()

    @staticmethod
    def from_surface(vertices_mm: np.ndarray, triangles: np.ndarray) -> "SurfaceMesh":
        return SurfaceMesh.from_corners(triangles, vertices_mm[triangles], vertices_mm)

    def smoothing_operators(
        self, cells: np.ndarray, mass_weight: np.ndarray, stiffness_weight: np.ndarray, edge_at_cells: bool = False, dirichlet: bool = True
    ) -> tuple[sp.csc_matrix, "OperatorPattern"]:
        """P1 operators on the triangles ``cells`` (indices, m): H and its pattern (with Q).

        H = M + K (v, v): the mass M = Q^T diag(A mass_weight) Q plus the cotangent stiffness K
        with each triangle weighted by ``stiffness_weight`` (m,), summed into the cached pattern
        of these cells (``operator_pattern``): no sparse assembly per call. The smoothed field
        vanishes on the surface's free edge, and with ``edge_at_cells`` on the cells' own
        boundary too (the layer ends there); elsewhere the boundary is natural. Without
        ``dirichlet`` it is natural everywhere.
        """
        pattern = self.operator_pattern(cells, edge_at_cells, dirichlet)
        # One 3 x 3 element matrix per triangle, row-major in (m, 9): mass A m / 9 for every
        # ordered pair of corners (Q^T diag(A m) Q) plus the cotangent stiffness, where the edge
        # opposite corner i carries w cot_i / 2 (off-diagonal -w cot_i / 2 at (j, k) and (k, j),
        # diagonal the sum over the corner's two edges).
        half = 0.5 * self.cotangents[cells] * np.asarray(stiffness_weight, float)[:, None]  # (m, 3)
        element = np.empty((half.shape[0], 9))
        element[:, [0, 4, 8]] = half.sum(axis=1)[:, None] - half
        element[:, [5, 7]] = -half[:, [0]]
        element[:, [2, 6]] = -half[:, [1]]
        element[:, [1, 3]] = -half[:, [2]]
        element += (self.area_mm2[cells] * np.asarray(mass_weight, float) / 9.0)[:, None]
        return pattern.matrix(pattern.sum_at_slots(element)), pattern

    def coarse_space(self, cells: np.ndarray, edge_at_cells: bool, dirichlet: bool, size_mm: float) -> "CoarseSpace":
        """The coarse space about ``size_mm`` across on the triangles ``cells`` (``coarse_transfer``),
        built once per cell set (kept with its operator patterns). Needs ``vertices_mm``."""
        if self.vertices_mm is None:
            raise ValueError("a coarse smoothing space needs the surface's vertex coordinates (SurfaceMesh.from_surface)")
        fine = self.operator_pattern(cells, edge_at_cells, dirichlet)  # also starts this cell set's memo
        key = ("coarse", edge_at_cells, dirichlet, float(size_mm))
        if key not in self.memo:
            fixed = self.fixed_vertices(cells, edge_at_cells, dirichlet)
            used = np.zeros(fixed.shape[0], bool)
            used[self.triangles[cells]] = True
            kept, edge = np.flatnonzero(used & ~fixed), np.flatnonzero(used & fixed)  # kept: the fine space's vertices, in its order
            self.memo[key] = CoarseSpace.build(fine, coarse_transfer(self.vertices_mm, self.triangles[cells], kept, edge, size_mm))
        return self.memo[key]

    def fixed_vertices(self, cells: np.ndarray, edge_at_cells: bool, dirichlet: bool) -> np.ndarray:
        """(n_vertices,) bool: where the smoothed field vanishes (``smoothing_operators``)."""
        if not dirichlet:
            return np.zeros(self.free_edge_vertex.shape[0], bool)
        if edge_at_cells:
            return self.free_edge_vertex | self.boundary_of(cells)
        return self.free_edge_vertex

    def operator_pattern(self, cells: np.ndarray, edge_at_cells: bool = False, dirichlet: bool = True) -> "OperatorPattern":
        """The sparsity of the operators on the triangles ``cells`` (indices, m), built once per cell set.

        Consecutive time points of a run usually share their cell set (the whole surface when the
        band around the candidates covers most of it), so the patterns of the last cell set are
        kept and reused. A new cell set (the threshold law's layer is its candidates, which change
        at every time point) is cut from the whole surface's pattern (``surface_pairs``), the
        same pattern as assembling its pairs, at 0.4x the cost on the 30k-spring ankle.
        ``edge_at_cells``, ``dirichlet``: see ``smoothing_operators``.
        """
        key = np.asarray(cells).tobytes()
        if self.memo.get("cells") != key:
            self.memo.clear()
            self.memo["cells"] = key
        cached = self.memo.get((edge_at_cells, dirichlet))
        if cached is not None:
            return cached
        tri = self.triangles[cells]
        free = self.fixed_vertices(cells, edge_at_cells, dirichlet)
        # The cells' pattern is the whole surface's restricted to the pairs the cells hold, on the
        # vertices they use off the free edge (where the smoothed field vanishes), numbered in
        # the surface's order: O(n) masks, no sorting per cell set (``surface_pairs``).
        kept = np.zeros(free.shape[0], bool)
        kept[tri] = True
        kept &= ~free
        renumber = np.cumsum(kept) - 1
        n_v = int(kept.sum())
        row, col, surface_slots = self.surface_pairs
        pairs = surface_slots[cells]  # (m, 9)
        entry = np.zeros(row.shape[0], bool)
        entry[pairs] = True
        entry &= kept[row] & kept[col]
        position = np.cumsum(entry) - 1
        indptr = np.zeros(n_v + 1, np.int64)
        np.cumsum(np.bincount(renumber[col[entry]], minlength=n_v), out=indptr[1:])
        slots = np.where(entry[pairs], position[pairs], -1)
        q = _corner_means(np.where(kept[tri], renumber[tri], -1), n_v)
        pattern = OperatorPattern(renumber[row[entry]], indptr, slots, q, tri.shape[0] == self.triangles.shape[0])
        self.memo[(edge_at_cells, dirichlet)] = pattern
        return pattern


def _corner_means(corner_vertex: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """Q (m, n_vertices), Q_tv = 1/3 for each of triangle t's corners ``corner_vertex`` (m, 3)
    int that is a vertex (-1: none), built in canonical CSR form directly (no COO sort)."""
    columns = np.sort(corner_vertex, axis=1)
    kept = columns >= 0
    if np.any((columns[:, 1:] == columns[:, :-1]) & kept[:, 1:]):  # a corner twice: its weights add up
        m = columns.shape[0]
        return sp.csr_matrix((np.full(int(kept.sum()), 1.0 / 3.0), (np.repeat(np.arange(m), 3)[kept.ravel()], columns[kept])), shape=(m, n_vertices))
    indptr = np.zeros(columns.shape[0] + 1, np.int64)
    np.cumsum(kept.sum(axis=1), out=indptr[1:])
    indices = columns[kept]
    return sp.csr_matrix((np.full(indices.shape[0], 1.0 / 3.0), indices, indptr), shape=(columns.shape[0], n_vertices))


# --------------------------------------------------------------------------- the compliance


@dataclass(frozen=True)
class SmoothingTerm:
    """One term sigma Z^T H^-1 Z of the compliance (module docstring): Z = Q^T diag(weight)."""

    sigma: float  # +1 or -1
    z_t: sp.csr_matrix  # (m, v) Z^T in mm/MPa
    h: sp.csc_matrix  # (v, v) canonical CSC, mm^3/MPa
    weight: np.ndarray  # (m,) c_nl in mm/MPa
    pattern: OperatorPattern  # H's sparsity, slots and ordering (SurfaceMesh.operator_pattern)
    coarse: CoarseSpace | None = None  # H, Z on a coarse space (H_c, Z_c, pattern its own), or None: on the springs' vertices

    @property
    def z(self) -> sp.csc_matrix:
        """(v, m): Z, a view of ``z_t``."""
        return self.z_t.T

    def coupled_data(self, spring_weight: np.ndarray) -> np.ndarray:
        """Data (nnz,) of H + sigma Z diag(spring_weight) Z^T on H's pattern.

        Z diag(x) Z^T = Q^T diag(c_nl^2 x) Q puts c_nl^2 x / 9 on every corner pair of each
        triangle, all of them entries of H, so only H's data changes. On a coarse space, Q P
        in place of Q (``CoarseSpace.pair_sums``).
        """
        if self.coarse is None:
            return self.h.data + self.pattern.sum_at_slots(self.sigma * self.weight**2 * spring_weight / 9.0)
        return self.h.data + self.coarse.pair_sums @ (self.sigma * self.weight**2 * spring_weight)


@dataclass(frozen=True)
class LayerCompliance:
    """w = C f on a set of springs: C = diag(local) + sum_i sigma_i Z_i^T H_i^-1 Z_i (module docstring).

    ``local`` is c_loc / A in mm/N. No term means no coupling (independent springs); the terms are
    the symbol's (one for the Pade, two for the two-pole) for each layer (two for a sandwich).
    The contact solve works on the terms' vertex fields stacked, z = (sigma H)^-1 Z f with
    Z = [Z_1; Z_2 ...] and sigma H = diag(sigma_i H_i), so that w = local f + Z^T z.
    """

    local_mm_per_n: np.ndarray  # (m,)
    terms: tuple[SmoothingTerm, ...] = ()
    reuse: dict | None = field(default=None, compare=False, repr=False)  # the last factor (factorise_coupled)

    @property
    def coupled(self) -> bool:
        return bool(self.terms)

    @functools.cached_property
    def z(self) -> sp.csr_matrix:
        """(V, m): the terms' Z stacked (V the sum of their vertex counts), row-major (the
        two-pole's block product); a product with a vector takes the view ``z_t.T``."""
        return self.z_t.T.tocsr()

    @functools.cached_property
    def _signed_block(self) -> sp.csc_matrix:
        """diag(sigma_i H_i) (V, V), the part of the coupled matrix that does not depend on the weights."""
        return sp.block_diag([t.sigma * t.h for t in self.terms], format="csc")

    @functools.cached_property
    def z_t(self) -> sp.csr_matrix:
        """(m, V): Z^T, the terms' Z^T side by side, row-major."""
        return sp.hstack([t.z_t for t in self.terms]).tocsr() if len(self.terms) > 1 else self.terms[0].z_t

    def factorise_coupled(self, spring_weight: np.ndarray):
        """Solve with sigma H + Z diag(spring_weight) Z^T (V, V) for weights (m,) in N/mm: solve(rhs).

        The active-set iteration and the viscoelastic increment ask for matrices that differ from
        the last factored one in a few springs' weights only (the springs that changed state), so
        the last factor is kept (``reuse``, shared by the layers built on the same operators): the
        same weights reuse it as it is, a few changed weights (at most ``low_rank_max``) correct it
        by the Woodbury identity (``LowRankUpdate``, exact to round-off), and more refactor.
        """
        reuse = self.reuse
        if reuse is None:
            return self._factorise(spring_weight)
        base = reuse.get("base")
        key = self._operator_key()
        if base is not None and base.matches(key, spring_weight.shape[0]):
            changed = np.flatnonzero(spring_weight != base.weight)
            if changed.size == 0:
                return base.solve
            if changed.size <= self.low_rank_max:
                return base.updated(self.z_t, changed, spring_weight[changed] - base.weight[changed])
        solve = self._factorise(spring_weight)
        reuse["base"] = LowRankUpdate(key, spring_weight.copy(), solve)
        return solve

    @property
    def low_rank_max(self) -> int:
        """Past this many changed weights a refactorisation is cheaper than the Woodbury correction
        (the checked LDL^T's factorisation with a new ordering, on cells that change at every time
        point, costs more single solves than a Cholesky's or one on a kept ordering)."""
        return LOW_RANK_MAX_INDEFINITE if len(self.terms) > 1 and not self.stacked else LOW_RANK_MAX

    @property
    def definite(self) -> bool:
        """Whether the stacked matrix sigma H + Z diag(x) Z^T is definite: its terms have one sign
        (a Pade layer, a Pade sandwich), so it is sigma times an SPD matrix (``_factorise``)."""
        return len({t.sigma for t in self.terms}) == 1

    @property
    def stacked(self) -> bool:
        """Whether several terms' matrix is assembled on their stacked pattern (``_stack``): where
        the terms' patterns are kept over the run (the layer over the whole surface, or its
        coarse space), so the pattern is built once. A layer whose cells change at every time
        point (the threshold law's candidates) assembles its matrix by sparse products instead:
        there building the stacked pattern at each time point cost more than it saved (docs/method.md)."""
        return len(self.terms) > 1 and all(t.pattern.whole_surface for t in self.terms)

    @functools.cached_property
    def _stack(self) -> tuple[StackedPattern, np.ndarray, sp.csr_matrix]:
        """More than one term: their stacked pattern (kept in ``reuse`` over the layers built on
        the same operator patterns: a run's time points on one cell set), sigma H's data in it
        and the product giving Z diag(x) Z^T's (``StackedPattern``)."""
        patterns = tuple(t.pattern for t in self.terms)
        kept = None if self.reuse is None else self.reuse.get("stack")
        if kept is None or len(kept[0]) != len(patterns) or not all(a is b for a, b in zip(kept[0], patterns)):
            kept = (patterns, StackedPattern.build(list(patterns), self.z_t))
            if self.reuse is not None:
                self.reuse["stack"] = kept
        stack = kept[1]
        return stack, stack.blocks([t.sigma * t.h.data for t in self.terms]), stack.coupling(self.z_t)

    @property
    def _kept_ldl(self) -> KeptOrderingLDL:
        """The stacked indefinite matrices' LDL^T with its ordering kept (``KeptOrderingLDL``), shared
        over the layers on the same stacked pattern (a run's time points on one cell set)."""
        stack = self._stack[0]
        kept = None if self.reuse is None else self.reuse.get("ldl")
        if kept is None or kept.stack is not stack:
            kept = KeptOrderingLDL(stack, self.z_t)
            if self.reuse is not None:
                self.reuse["ldl"] = kept
        return kept

    def _operator_key(self) -> tuple:
        """What the factored matrix depends on besides the spring weights: each term's sign, its
        pattern (by identity), H's data and the weights c_nl of Z."""
        return tuple((t.sigma, id(t.pattern), t.h.data, t.weight) for t in self.terms)

    def _factorise(self, spring_weight: np.ndarray):
        """Factor of sigma H + Z diag(spring_weight) Z^T: solve(rhs).

        One term: sigma (H + sigma Z diag(x) Z^T), SPD (module docstring), by its pattern's
        banded Cholesky or CHOLMOD. More terms on a pattern kept over the run (``stacked``):
        assembled on their ``StackedPattern``; of one sign (a Pade sandwich's two) the matrix is
        sigma times an SPD one (docs/method.md, "Two layers: the sandwich"), factored as one
        term's is; of both signs (the two-pole's, a two-pole sandwich's four) it is indefinite and
        QDLDL's checked LDL^T (``indefinite_solve``) factors the pairs of the springs in contact.
        More terms on cells that change at every time point: assembled by sparse products, by
        the checked LDL^T whatever their signs. Its pattern follows the contact set (the terms'
        fields are coupled only through springs in contact), so the ordering is found anew each
        time: one pattern holding every spring of the layer would keep it, but on the gap law's
        30k-spring layer (the whole surface) its fill made each factorisation 2x slower (217 ms
        against 111 ms), and one growing with the springs in contact over a time point was found
        again at 56 of 76 factorisations (docs/method.md).
        """
        sigma = self.terms[0].sigma
        if len(self.terms) == 1:
            solve = self.terms[0].pattern.factorise(self.terms[0].coupled_data(spring_weight))
        elif not self.stacked:
            return indefinite_solve((self._signed_block + self.z @ (self.z_t.multiply(spring_weight[:, None])).tocsc()).tocsc())
        else:
            stack, signed_blocks, coupling = self._stack
            data = signed_blocks + coupling @ spring_weight
            if not self.definite:
                return self._kept_ldl.factorise(data, spring_weight)
            solve = stack.pattern.factorise(sigma * data)
        return solve if sigma > 0 else (lambda rhs: -solve(rhs))

    def deflection(self, force_n: np.ndarray) -> np.ndarray:
        """Surface deflection w (m,) in mm under spring forces f (m,) in N."""
        w = self.local_mm_per_n * force_n
        for term in self.terms:
            w = w + term.sigma * (term.z_t @ term.pattern.factorise(term.h.data)(term.z @ force_n))
        return w


def layer_compliance(
    mesh: SurfaceMesh,
    cells: np.ndarray,
    thickness_mm: np.ndarray,
    youngs_modulus_mpa: float,
    poissons_ratio: float,
    edge_at_cells: bool = False,
    symbol: LayerSymbol | None = None,
    smoothing_resolution: float = 0.0,
) -> LayerCompliance:
    """The thin-layer compliance on the springs ``cells`` (indices, m) with local thickness in mm.

    ``thickness_mm``: (m,) (or a number) for one layer bonded to its bone against a rigid body;
    (L, m) for L layers, each bonded to its own bone and frictionless against the next (the
    sandwich, module docstring): their compliances add, the local terms into one and each layer
    with its own smoothing terms (a layer of zero thickness everywhere brings none).
    ``edge_at_cells``: the layer ends at the boundary of ``cells`` (a free lateral face there),
    rather than going on beyond them with a natural cut. ``symbol``: the layer's symbol at
    ``poissons_ratio`` (:data:`edem.layer_symbols.LAYER_SYMBOLS`; None: the Pade).
    ``smoothing_resolution`` > 0: each term is solved on a coarse space (:mod:`edem.coarse_space`)
    of this many cells per smoothing length sqrt(b) h (at its layer's median h), where
    those cells are at least COARSE_MIN_SPRINGS springs across; 0: on the springs' vertices."""
    given = np.asarray(thickness_mm, float)
    layers = np.broadcast_to(given, given.shape[:1] + cells.shape) if given.ndim == 2 else np.broadcast_to(given, cells.shape)[None]
    h = layers[0] if layers.shape[0] == 1 else layers.sum(axis=0)
    # The gap laws' layer over the whole surface has the same cells and thickness at every time
    # point of a run: its compliance is built once (kept with the cells' operator patterns).
    key = (np.asarray(cells).tobytes(), layers.shape[0], np.ascontiguousarray(layers).tobytes(), youngs_modulus_mpa, poissons_ratio,
           edge_at_cells, symbol, smoothing_resolution)
    kept = mesh.memo.get("layer")
    if kept is not None and kept[0] == key:
        return kept[1]
    g = youngs_modulus_mpa / (2.0 * (1.0 + poissons_ratio))
    model = pade_symbol(poissons_ratio) if symbol is None else symbol
    coarse_cells = smoothing_resolution > 0.0 and cells.size > 0
    if coarse_cells:  # (the springs' size: only where a coarse space may be built)
        spring_mm = float(np.sqrt(2.0 * np.median(mesh.area_mm2[cells])))
    # A sandwich's layer whose thickness did not change (M's, on the gap laws) keeps its terms
    # while the other's are built again (F's, measured where each ray meets F).
    built, terms = mesh.memo.get("terms", {}), []
    for layer_h in layers:
        if not np.any(layer_h):
            continue  # no cartilage on this side: a rigid body, no term
        for strength, b, dirichlet in zip(model.strengths, model.screenings, model.dirichlet):
            size_mm = np.sqrt(b) * float(np.median(layer_h)) / smoothing_resolution if coarse_cells else 0.0
            term_key = (key[0], np.ascontiguousarray(layer_h).tobytes(), g, strength, b, dirichlet, edge_at_cells, size_mm)
            term = built.get(term_key)
            if term is None:
                term = _smoothing_term(mesh, cells, layer_h, g, strength, b, dirichlet, edge_at_cells, size_mm, spring_mm if coarse_cells else 0.0)
            terms.append((term_key, term))
    mesh.memo["terms"] = dict(terms)
    layer = LayerCompliance(model.local * (h / g) / mesh.area_mm2[cells], tuple(term for _, term in terms), mesh.memo.setdefault("factor", {}))
    mesh.memo["layer"] = (key, layer)
    return layer


def _smoothing_term(
    mesh: SurfaceMesh, cells: np.ndarray, thickness_mm: np.ndarray, g: float, strength: float, b: float, dirichlet: bool,
    edge_at_cells: bool, size_mm: float, spring_mm: float,
) -> SmoothingTerm:
    """One layer's term s / (1 + b (kh)^2) on the cells (its thickness (m,) mm, shear modulus
    ``g`` MPa; module docstring), on a coarse space of cells ``size_mm`` across where that is at
    least COARSE_MIN_SPRINGS springs (``spring_mm``) across."""
    h = thickness_mm
    # S = (c_nl - div(b h^2 c_nl grad))^-1 c_nl (module docstring, variable thickness).
    c_nl = np.broadcast_to(abs(strength) * (h / g), cells.shape)
    smoothing, pattern = mesh.smoothing_operators(cells, c_nl, b * h * h * c_nl, edge_at_cells, dirichlet)
    if not np.all(c_nl):
        # Where the layer has no thickness the term vanishes: a vertex whose triangles all have
        # c_nl = 0 has an empty row in H and in Z, so its field is 0 for any positive diagonal.
        slots = np.flatnonzero(pattern.indices == np.repeat(np.arange(pattern.n_vertices), np.diff(pattern.indptr)))
        empty = slots[smoothing.data[slots] == 0.0]
        smoothing.data[empty] = smoothing.data[slots].max()
    coarse = mesh.coarse_space(cells, edge_at_cells, dirichlet, size_mm) if size_mm > 0.0 and size_mm >= COARSE_MIN_SPRINGS * spring_mm else None
    q = pattern.q if coarse is None else coarse.pattern.q  # Z^T = diag(c_nl) Q: Q's rows scaled, no sparse product
    z_t = sp.csr_matrix((q.data * np.repeat(c_nl, np.diff(q.indptr)), q.indices, q.indptr), shape=q.shape)
    if coarse is not None:
        smoothing, pattern = coarse.operator(smoothing), coarse.pattern
    return SmoothingTerm(float(np.sign(strength)), z_t, smoothing, c_nl, pattern, coarse)
