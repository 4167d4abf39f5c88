"""Coupled thin-layer cartilage: a bonded elastic layer's lateral coupling as a sparse surface operator.

Exact compliance of a bonded layer (plane strain)
--------------------------------------------------
A layer 0 < z < h of an isotropic solid (shear modulus G, Poisson's ratio nu) is bonded to a
rigid base at z = 0 (u_x = u_z = 0) and loaded on its frictionless top z = h by a normal pressure
p cos(kx) (sigma_zz = -p cos kx, sigma_xz = 0). With the Airy function
phi = [(A + B kz) cosh kz + (C + D kz) sinh kz] cos kx (sigma_xx = phi_zz, sigma_zz = phi_xx,
sigma_xz = -phi_xz), plane-strain Hooke's law and the four boundary conditions give A..D, and the
top deflection w = -u_z(h) = C(k) p cos kx with, for q = kh and kappa = 3 - 4 nu,

    C(k) G / h = (1 - nu) (kappa sinh 2q - 2q) / (2q [kappa sinh^2 q + q^2 + 4 (1 - nu)^2]).

Limits: q -> 0 gives h / E' (E' = 2G(1 - nu)/(1 - 2nu), the confined modulus: the independent
spring of the bed); q -> inf gives (1 - nu)/(G k), the half-space. Its Taylor series in x = q^2 is

    C G / h = c0 + c1 x + c2 x^2 + ...,   c0 = (1 - 2nu) / (2(1 - nu)) = G / E',
    c1 = nu (4 nu - 1) / (6 (1 - nu)^2),
    c2 = -(16 nu^3 + 76 nu^2 - 30 nu + 3) / (120 (1 - nu)^3).

c1 = 1/3 at nu = 1/2 is the classical incompressible thin-layer law w = -(h^3 / 3G) lap p;
c2 < 0 for every nu in [0, 1/2].

[1/1] Pade in x
---------------
C G / h ~ (e + a x) / (1 + b x), e = c0, a = c1 + e b. For nu > 1/4 (c1 > 0), b = -c2 / c1 > 0
matches c1 and c2. For nu < 1/4 that b would be negative (a pole at small kh), so there
b = -2 c1 / e >= 0 instead: c0 and c1 are matched and the short-wave limit a / b = e / 2 stays
positive; at nu = 0 and nu = 1/4 (c1 = 0) the model is the independent springs exactly.
Largest relative error against the exact C for kh <= 1 (kh <= 2), see ``LayerSymbol.error_bound``:
nu 0: 3.0 % (22 %, the independent springs' own error); 0.1: 1.4 %; 0.2: 0.7 %; 0.3: 1.0 % (12 %);
0.42: 0.24 % (6.9 %); 0.45: 0.12 %; 0.49: 0.79 % (2.3 %); 0.499: 1.0 % (1.5 %).
The independent springs (C = h/E') are off by 29 % at nu 0.42 and 98 % at nu 0.499 for kh <= 1.
At short waves the Pade levels off at a/b while the layer stiffens as (1 - nu)/kh: 2-5x too
compliant at kh = 12, which widens contacts (docs/method.md, section 3). ``two_pole_symbol`` adds a
second, short-range term fitted over 0 <= kh <= 12; ``LAYER_SYMBOLS`` names both.

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
(``two_pole_symbol``) the bulge term vanishes there, the sag term is natural. Where the contact
solve cuts the surface to a band around the candidates (``edem.thin_layer_contact``), the layer goes on, and the cut is natural.
Where the layer itself ends inside the surface (the threshold law's cartilage fills the gap only
where the springs are candidates), its edge is free like the surface's (``edge_at_cells``).

Coarse smoothing space. The smoothed field varies over sqrt(b) h (about 2.5 mm for the Pade on
a 2 mm layer) while springs may be 0.3 mm apart, so with ``smoothing_resolution`` r > 0 a term
whose coarse cells sqrt(b) h / r are at least COARSE_MIN_SPRINGS springs across is solved on a
subspace of the P1 space: v = P v_c, P (v, V_c) the interpolation of a coarse triangulation
(``coarse_transfer``), with the Galerkin operators H_c = P^T H P and Z_c = P^T Z, so

    C_c = diag(c_loc / A) + sigma Z_c^T H_c^-1 Z_c.

It is symmetric; P H_c^-1 P^T <= H^-1 (an H-orthogonal projection), so for sigma = -1 the
coarse term removes less than the fine one: C_c >= C (still positive definite), converging to
it as P -> I (P = I once every vertex is a coarse one). The coarse functions sum to one where
none was dropped, so a uniform pressure on a layer without free edges still deflects it by
h p / E'; the coarse vertices on the free edge are dropped, so the field still vanishes there.
The coupled matrix keeps its form, sigma H_c + Z_c diag(x) Z_c^T, on the coarse pattern.

Factorisation. The vertex matrices are SPD and banded once renumbered by reverse Cuthill-McKee
(half-bandwidth about the square root of the vertex count on a surface patch), so LAPACK's banded
Cholesky factors them; it took 0.35-0.65x the time of SuperLU's symmetric-mode LU on the ankle
surfaces (1.1k-14k vertices). The ordering depends on the sparsity only and is found once per
cell set (``OperatorPattern``); past ``MAX_BANDED_HALF_WIDTH`` the sparse LU takes over. A
refactorisation on the same pattern keeps the factor's columns before the first one whose
entries changed and factors only the trailing block (``OperatorPattern._banded_cholesky``).
Fill-reducing sparse factors did not beat it on the stances' matrices (0.6k-14k vertices,
``benchmarks/bench_factorisations.py``, docs/method.md): QDLDL's LDL^T with its ordering kept
and only the numbers refactored took 1.2-3.6x the banded path's time, CHOLMOD through cholespy
(no numeric-only refactorisation) 3.1-6.2x, SuperLU 2.7-4.1x. The two-pole's block matrix is
indefinite; QDLDL factors it, each solve checked against its backward error (``indefinite_solve``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_solve_banded, lu_factor, lu_solve
from scipy.linalg.lapack import dpbtrf
from scipy.sparse.csgraph import dijkstra, reverse_cuthill_mckee
from scipy.sparse.linalg import splu

from geometries.errors import SolverError

# --------------------------------------------------------------------------- symbols


def exact_layer_compliance(kh: np.ndarray, poissons_ratio: float) -> np.ndarray:
    """C G / h of the bonded layer under p cos(kx) (module docstring), dimensionless, shape of ``kh``."""
    nu = poissons_ratio
    q = np.minimum(np.asarray(kh, float), 150.0)  # beyond, sinh overflows and C G/h = (1 - nu)/q anyway
    kappa = 3.0 - 4.0 * nu
    small = q < 1e-4
    qs = np.where(small, 1.0, q)
    value = (1.0 - nu) * (kappa * np.sinh(2.0 * qs) - 2.0 * qs) / (2.0 * qs * (kappa * np.sinh(qs) ** 2 + qs * qs + 4.0 * (1.0 - nu) ** 2))
    c0, c1, _ = taylor_coefficients(nu)
    return np.where(small, c0 + c1 * q * q, value)


def taylor_coefficients(poissons_ratio: float) -> tuple[float, float, float]:
    """(c0, c1, c2) of C G / h = c0 + c1 (kh)^2 + c2 (kh)^4 + ... (module docstring)."""
    nu = poissons_ratio
    c0 = (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))
    c1 = nu * (4.0 * nu - 1.0) / (6.0 * (1.0 - nu) ** 2)
    c2 = -(16.0 * nu**3 + 76.0 * nu**2 - 30.0 * nu + 3.0) / (120.0 * (1.0 - nu) ** 3)
    return c0, c1, c2


def pade_coefficients(poissons_ratio: float) -> tuple[float, float, float]:
    """(e, a, b) of C G / h ~ (e + a (kh)^2) / (1 + b (kh)^2), b >= 0 (module docstring)."""
    c0, c1, c2 = taylor_coefficients(poissons_ratio)
    if c1 > 0.0:
        b = -c2 / c1
    elif c1 < 0.0:
        b = -2.0 * c1 / c0
    else:
        b = 0.0
    return c0, c1 + c0 * b, b


@dataclass(frozen=True)
class LayerSymbol:
    """A rational model of the layer's compliance, C G / h ~ local + sum_i s_i / (1 + b_i (kh)^2).

    Each term s_i / (1 + b_i x) is one screened-Poisson smoothing on the surface (module docstring:
    w = c_loc p + sum_i s_i (h/G) S_i p). ``dirichlet[i]``: whether term i's smoothed field vanishes
    at a free edge (else the edge is natural for it).
    """

    local: float
    strengths: tuple[float, ...] = ()
    screenings: tuple[float, ...] = ()
    dirichlet: tuple[bool, ...] = ()

    def __call__(self, kh: np.ndarray) -> np.ndarray:
        x = np.asarray(kh, float) ** 2
        return self.local + sum(s / (1.0 + b * x) for s, b in zip(self.strengths, self.screenings))

    def error_bound(self, poissons_ratio: float, max_kh: float = 1.0) -> float:
        """Largest relative error against the exact compliance over 0 < kh <= max_kh."""
        kh = np.linspace(1e-3, max_kh, 4001)
        return float(np.max(np.abs(self(kh) / exact_layer_compliance(kh, poissons_ratio) - 1.0)))


def pade_symbol(poissons_ratio: float) -> LayerSymbol:
    """The [1/1] Pade as a LayerSymbol: local a / b and one term -c1 / b (none where b = 0)."""
    e, a, b = pade_coefficients(poissons_ratio)
    _, c1, _ = taylor_coefficients(poissons_ratio)
    if b == 0.0 or abs(c1) <= 1e-12 * e * b:
        return LayerSymbol(e)
    return LayerSymbol(a / b, (-c1 / b,), (b,), (True,))


#: The two-pole symbol is fitted to the exact compliance over 0 <= kh <= this: the shortest waves
#: a spring mesh resolves on a layer, pi h / spacing (6-12 for a 2 mm layer on 0.5-1 mm springs).
TWO_POLE_MAX_KH = 12.0


def _two_pole_terms(c0: float, c1: float, b: np.ndarray, x: np.ndarray, exact: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For screenings b (k, 2) with b[:, 0] < b[:, 1]: the least-squares relative fit over x of
    local + s1/(1 + b1 x) + s2/(1 + b2 x) with C(0) = c0 and C'(0) = c1 held exactly.

    Returns (local (k,), strengths (k, 2), rms relative error (k,)). The two constraints leave s1
    free: C = c0 + s1 u1 + s2 u2 with u_i = 1/(1 + b_i x) - 1 and s2 = -(c1 + s1 b1) / b2.
    """
    u1 = 1.0 / (1.0 + b[:, :1] * x) - 1.0
    u2 = 1.0 / (1.0 + b[:, 1:] * x) - 1.0
    base = (c0 - c1 / b[:, 1:] * u2) / exact  # (k, n) relative, at s1 = 0
    slope = (u1 - b[:, :1] / b[:, 1:] * u2) / exact
    s1 = ((1.0 - base) * slope).sum(axis=1) / np.maximum((slope * slope).sum(axis=1), 1e-300)
    s2 = -(c1 + s1 * b[:, 0]) / b[:, 1]
    rms = np.sqrt(((base + s1[:, None] * slope - 1.0) ** 2).mean(axis=1))
    return c0 - s1 - s2, np.column_stack([s1, s2]), rms


def _definiteness_margin(local: np.ndarray, s: np.ndarray, b: np.ndarray) -> np.ndarray:
    """local + min(0, min over x >= 0 of g(x)), g(x) = s1/(1 + b1 x) + s2/(1 + b2 x): a lower bound
    (in h/G) of the compliance C on any mesh (``two_pole_symbol``). Rows of s, b: (k, 2).

    With one mass M and stiffness K, both H_i = M + b_i K are diagonal in the basis of K v = lam M v,
    where the two terms weigh each mode by g(lam); bounded below by min(0, min g) times a
    projection, they leave C >= local + min(0, min g). Holding a negative term's field at zero on
    an edge only raises it. g is smallest at x = 0, at infinity (where it is 0) or at its one
    stationary point, which a pair of opposite signs can have.
    """
    lowest = np.minimum(s.sum(axis=1), 0.0)  # g(0); g(inf) = 0
    with np.errstate(invalid="ignore", divide="ignore"):
        # g'(x) = 0: (1 + b2 x) sqrt(-s1 b1) = (1 + b1 x) sqrt(s2 b2) for s1 < 0 < s2 (and the mirror).
        r1, r2 = np.sqrt(np.abs(s[:, 0] * b[:, 0])), np.sqrt(np.abs(s[:, 1] * b[:, 1]))
        x = (r2 - r1) / (r1 * b[:, 1] - r2 * b[:, 0])
        inner = s[:, 0] / (1.0 + b[:, 0] * x) + s[:, 1] / (1.0 + b[:, 1] * x)
    stationary = (s[:, 0] * s[:, 1] < 0.0) & np.isfinite(x) & (x > 0.0)
    return local + np.minimum(lowest, np.where(stationary, inner, 0.0))


@functools.lru_cache(maxsize=64)
def two_pole_symbol(poissons_ratio: float) -> LayerSymbol:
    """Two screened-Poisson terms fitted to the exact compliance for 0 <= kh <= TWO_POLE_MAX_KH.

    The Pade has one term, so it levels off at short waves (C -> a/b) where the layer, like a
    half-space, gets stiffer as (1 - nu)/kh: its contact edges are too soft. Two terms of opposite
    sign follow the exact curve over the whole range (a bulge term, and a short-range term for the
    surface's sag around a load). Fit: C(0) = G/E' and the thin-layer coefficient c1 exactly, the
    rest by least squares in relative error (a 61 x 61 grid of screenings, then Nelder-Mead), among
    the fits whose compliance stays, on any mesh, above half the smaller of its own limits C(0) =
    G/E' and C(inf) = local (``_definiteness_margin``; the Pade's bound is G/E' itself). A term
    with s_i < 0 (the bulge) vanishes on a free edge like the Pade's; a term with s_i > 0 is
    natural there (held at zero it would lower the bound). Largest relative error for
    0 <= kh <= 12: 4.2 % (nu -> 1/2), 2-4 % from nu 0 up, 4.7 % at nu = -0.5.
    """
    from scipy.optimize import minimize

    c0, c1, _ = taylor_coefficients(poissons_ratio)
    q = np.concatenate([np.linspace(0.0, 1.0, 51), np.geomspace(1.0, TWO_POLE_MAX_KH, 200)[1:]])
    x, exact = q * q, exact_layer_compliance(q, poissons_ratio)
    grid = np.linspace(np.log(1e-3), np.log(1e2), 61)
    i, j = np.triu_indices(grid.size, 1)
    b = np.exp(np.column_stack([grid[i], grid[j]]))
    local, s, rms = _two_pole_terms(c0, c1, b, x, exact)
    rms = np.where(_definiteness_margin(local, s, b) >= 0.5 * np.minimum(local, c0), rms, np.inf)

    def objective(log_b: np.ndarray) -> float:
        pair = np.exp(np.sort(log_b))[None]
        if pair[0, 1] <= pair[0, 0] * (1.0 + 1e-9):
            return np.inf
        lo, st, err = _two_pole_terms(c0, c1, pair, x, exact)
        return float(err[0]) if _definiteness_margin(lo, st, pair)[0] >= 0.5 * min(float(lo[0]), c0) else np.inf

    best = int(np.argmin(rms))
    if not np.isfinite(rms[best]):
        raise ValueError(f"no positive definite two-pole fit at Poisson's ratio {poissons_ratio}")
    refined = minimize(objective, np.log(b[best]), method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9})
    pair = np.exp(np.sort(refined.x))[None] if refined.fun <= rms[best] else b[best][None]
    lo, st, _ = _two_pole_terms(c0, c1, pair, x, exact)
    strengths = tuple(float(v) for v in st[0])
    return LayerSymbol(float(lo[0]), strengths, tuple(float(v) for v in pair[0]), tuple(v < 0.0 for v in strengths))


#: ``[cartilage] thin_layer_symbol``: the rational model of the layer's compliance.
LAYER_SYMBOLS = {"pade": pade_symbol, "two-pole": two_pole_symbol}


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
        area = 0.5 * np.linalg.norm(np.cross(corners_mm[:, 1] - corners_mm[:, 0], corners_mm[:, 2] - corners_mm[:, 0]), axis=1)
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
        pattern = OperatorPattern(renumber[row[entry]], indptr, slots, q)
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


# Past this half-bandwidth (after reverse Cuthill-McKee) the sparse LU is the cheaper factor: on
# the ankle surfaces LAPACK's banded Cholesky took 0.35-0.65x SuperLU's time at half-bandwidths
# 47-156 (1.1k-14k vertices), a ratio growing about like the bandwidth (benchmarks/bench_thin_layer.py).
MAX_BANDED_HALF_WIDTH = 256


@dataclass
class OperatorPattern:
    """Sparsity of H = M + K on a cell set (v, v), canonical CSC, and the transfer Q (m, v).

    ``slots[t]`` (9,) int: where triangle t's corner pair (i, j), row-major, sits in the
    matrix's data, -1 for a pair on the free edge; Q^T diag(x) Q is then the pattern with x / 9
    added at the slots (no sparse product, no re-assembly). The band layout of the factorisation
    (an ordering and where each stored entry goes) depends on the pattern only, so it is found
    at the first factorisation and reused; so is the last band factor, in part
    (``_banded_cholesky``).
    """

    indices: np.ndarray
    indptr: np.ndarray
    slots: np.ndarray  # (m, 9) int
    q: sp.csr_matrix  # (m, v)
    #: the stored lower entries and band factor of the last banded factorisation on this pattern
    last_factor: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @property
    def n_vertices(self) -> int:
        return self.indptr.shape[0] - 1

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n_vertices, self.n_vertices))

    def sum_at_slots(self, per_pair: np.ndarray) -> np.ndarray:
        """Matrix data (nnz,) from values per triangle and corner pair (m, 9), or per triangle
        (m,) for the same value on its nine pairs, summed where they meet."""
        kept, slot = self.kept_pairs
        weights = per_pair.ravel()[kept] if per_pair.ndim == 2 else per_pair[kept // 9]
        return np.bincount(slot, weights=weights, minlength=self.indices.shape[0])

    @functools.cached_property
    def kept_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The corner pairs off the free edge: their flat positions in (m, 9) and their slots."""
        kept = np.flatnonzero(self.slots.ravel() >= 0)
        return kept, self.slots.ravel()[kept]

    @functools.cached_property
    def band(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """(ordering, the stored entries in the lower band, their flat positions in LAPACK's band
        storage (column-major, as LAPACK reads it), half-width) of the reverse Cuthill-McKee
        renumbering; built on first use."""
        n = self.n_vertices
        # The pattern is symmetric, so its CSC arrays read as CSR are the same graph (no conversion).
        graph = sp.csr_matrix((np.ones(self.indices.shape[0]), self.indices, self.indptr), shape=(n, n))
        order = reverse_cuthill_mckee(graph, symmetric_mode=True).astype(np.int64)
        position = np.empty(n, np.int64)
        position[order] = np.arange(n)
        row = position[self.indices]
        col = position[np.repeat(np.arange(n), np.diff(self.indptr))]
        lower = np.flatnonzero(row >= col)  # LAPACK's lower band storage: ab[i - j, j] = A[i, j]
        width = int((row - col)[lower].max(initial=0))
        return order, lower, col[lower] * (width + 1) + (row - col)[lower], width

    def factorise(self, data: np.ndarray):
        """Factor of the SPD matrix with this pattern and ``data`` (nnz,); returns solve(rhs (v,) or (v, k)).

        Banded Cholesky in reverse Cuthill-McKee order up to MAX_BANDED_HALF_WIDTH (of the
        trailing part only where the last factor on this pattern can be kept, ``_banded_cholesky``),
        SuperLU's symmetric-mode LU (diagonal pivots, minimum-degree ordering) beyond.
        """
        n = self.n_vertices
        if n == 0:  # every vertex on a free edge: the smoothed field vanishes, the layer is local
            return np.zeros_like
        order, lower, flat, width = self.band
        try:
            if width > MAX_BANDED_HALF_WIDTH:
                return splu(self.matrix(data), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}).solve
            entries = data[lower]
            factor = self._banded_cholesky(entries)
        except (np.linalg.LinAlgError, RuntimeError) as error:  # RuntimeError: SuperLU's "singular matrix"
            raise SolverError(f"the coupled thin-layer matrix is not positive definite ({error})") from None
        self.last_factor = (entries, factor)

        def solve(rhs: np.ndarray) -> np.ndarray:
            out = np.empty_like(rhs)
            out[order] = cho_solve_banded((factor, True), rhs[order], overwrite_b=True, check_finite=False)
            return out

        return solve

    def _banded_cholesky(self, entries: np.ndarray) -> np.ndarray:
        """LAPACK's lower band factor (width + 1, v), column-major, of the matrix whose lower band
        holds ``entries`` (the stored lower entries, in ``band`` order).

        Only the trailing part is refactored where the matrix differs from the last one factored
        on this pattern from band column k on: with A = L L^T split at k, L11 and L21 depend on
        A11 and A21 alone and are kept, and L22 = chol(A22 - L21 L21^T), where L21 L21^T touches
        A22's leading w x w block only (w the half-width). The active-set iterations change the
        weights of the springs at the contact's edge, so on the gap law's layer (the whole surface,
        the same operators over a run) k sat at 0.12-0.6 of the vertices on the 30k-spring ankle.
        Exact to round-off.
        """
        order, lower, flat, width = self.band
        n = self.n_vertices
        band = np.zeros((width + 1) * n)
        band[flat] = entries
        band = band.reshape((width + 1, n), order="F")  # column j of the band is contiguous
        last = self.last_factor
        start = 0
        if last is not None:
            changed = np.flatnonzero(entries != last[0])
            start = int(flat[changed].min()) // (width + 1) if changed.size else n  # the first column that differs
        if start == n:
            return last[1]
        if start > 0:
            factor = last[1]
            band[:, :start] = factor[:, :start]
            # L21: rows start .. start + w - 1, columns start - w .. start - 1, L[i, j] = factor[i - j, j].
            rows = np.arange(start, min(start + width, n))
            cols = np.arange(max(start - width, 0), start)
            offset = rows[:, None] - cols[None, :]
            l21 = np.where(offset <= width, factor[np.minimum(offset, width), cols[None, :]], 0.0)
            a, b = _lower_triangle(rows.size)
            band[a - b, start + b] -= (l21 @ l21.T)[a, b]
        trailing, info = dpbtrf(band[:, start:], lower=1, overwrite_ab=1)  # in place: the view is column-major
        if info > 0:
            raise np.linalg.LinAlgError(f"leading minor {start + info} is not positive definite")
        if not np.shares_memory(trailing, band):  # LAPACK worked on a copy
            band[:, start:] = trailing
        return band


@functools.lru_cache(maxsize=8)
def _lower_triangle(n: int) -> tuple[np.ndarray, np.ndarray]:
    """np.tril_indices(n), kept (read-only): a run refactors with the same half-width over and over."""
    rows, cols = np.tril_indices(n)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


# --------------------------------------------------------------------------- the coarse smoothing space

#: A term is solved on a coarse space only where its coarse size is at least this many springs
#: across (the side sqrt(2 A) of the median triangle): below, the space keeps most of the
#: vertices (1 mm cubes kept 0.74 of them on 0.94 mm springs) and building it costs more than
#: the smaller factor saves (benchmarks/bench_coarse_smoothing.py).
COARSE_MIN_SPRINGS = 2.0


def _ranges(start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The positions start[i], ..., start[i] + count[i] - 1 of every i, concatenated (a CSR
    matrix's entries of chosen rows, given their indptr starts and lengths)."""
    return np.repeat(start - (np.cumsum(count) - count), count) + np.arange(int(count.sum()))


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
    triangulation, about ``size_mm`` across, of the surface ``triangles`` (m, 3) (module docstring,
    "Coarse smoothing space").

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
    triangle = around.indices[_ranges(around.indptr[np.maximum(own, 0)], count)]
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
    vertices: ``pair_slot`` and ``pair_product`` ((QP)_ta (QP)_tb) list them spring by spring,
    spring t's from ``pair_start[t]`` to ``pair_start[t + 1]``, so the coupled matrix's data is
    one bincount over the springs of nonzero weight (``SmoothingTerm.coupled_data``).
    """

    transfer: sp.csr_matrix
    pattern: OperatorPattern
    keys: np.ndarray  # (nnz,) column * V_c + row of each stored entry (sorted)
    pair_slot: np.ndarray
    pair_product: np.ndarray
    pair_start: np.ndarray  # (m + 1,)

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
        pattern = OperatorPattern(structure.indices, structure.indptr, np.zeros((0, 9), np.int64), qp)
        start = np.zeros(m + 1, np.int64)
        np.cumsum(count * count, out=start[1:])  # valid is row-major: spring by spring
        return CoarseSpace(transfer, pattern, keys, np.searchsorted(keys, b * n_c + a), (value[:, :, None] * value[:, None, :])[valid], start)

    def pairs_of(self, springs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the pairs' positions, their springs) of the springs (k,), spring by spring."""
        count = self.pair_start[springs + 1] - self.pair_start[springs]
        return _ranges(self.pair_start[springs], count), np.repeat(springs, count)

    def operator(self, fine_h: sp.csc_matrix) -> sp.csc_matrix:
        """H_c = P^T H P (V_c, V_c) on the coupled pattern."""
        product = (self.transfer.T @ fine_h @ self.transfer).tocoo()
        n_c = self.transfer.shape[1]
        data = np.zeros(self.keys.shape[0])
        np.add.at(data, np.searchsorted(self.keys, product.col * n_c + product.row), product.data)
        return self.pattern.matrix(data)


# Past this many changed spring weights the coupled matrix is refactored rather than corrected by
# the Woodbury identity: each changed weight costs one solve with the old factor, and on the ankle
# surfaces (14k vertices, half-bandwidth 156) a banded factorisation cost about 16 single solves
# (benchmarks/bench_thin_layer.py). The two-pole's indefinite block (QDLDL, each solve checked)
# cost 24-25 checked single solves a factorisation at 3k and 29k springs (3k and 29k unknowns), so
# it takes twice as many.
LOW_RANK_MAX = 8
LOW_RANK_MAX_INDEFINITE = 16


@dataclass
class LowRankUpdate:
    """A factor of A(w0) = sigma H + Z diag(w0) Z^T, reused for A(w) with w - w0 nonzero on k springs:

        A(w)^-1 = A0^-1 - Y (I + D Z_k^T Y)^-1 D Z_k^T A0^-1,   Y = A0^-1 Z_k,  D = diag(w - w0)_k,

    (the Woodbury identity; the k x k capacitance is nonsingular whenever A(w) is). The columns Y
    of the springs met so far are kept (up to 8 LOW_RANK_MAX of them), so a spring toggling back
    and forth is solved for once.
    """

    key: tuple  # LayerCompliance._operator_key() of the factored matrix
    weight: np.ndarray  # (m,) w0
    solve: object  # A0^-1
    columns: dict = field(default_factory=dict)  # spring -> its column of Y (V,)

    def matches(self, key: tuple, n_springs: int) -> bool:
        if self.weight.shape[0] != n_springs or len(key) != len(self.key):
            return False
        return all(a[:2] == b[:2] and np.array_equal(a[2], b[2]) and np.array_equal(a[3], b[3]) for a, b in zip(key, self.key))

    def updated(self, z_t: sp.csr_matrix, changed: np.ndarray, delta: np.ndarray):
        """solve(rhs) with A(w) for the weights changed by ``delta`` (k,) on the springs ``changed``
        (k,); ``z_t`` (m, V): Z^T."""
        z_k = _dense_columns(z_t, changed)  # (V, k): each spring's column has its triangle's corners
        new = [j for j in changed.tolist() if j not in self.columns]
        if len(self.columns) + len(new) > 8 * LOW_RANK_MAX:  # bounded memory: keep the columns in use
            self.columns = {j: self.columns[j] for j in changed.tolist() if j in self.columns}
        if new:
            solved = self.solve(z_k[:, np.searchsorted(changed, new)])
            self.columns.update(zip(new, solved.T))
        y = np.column_stack([self.columns[j] for j in changed.tolist()])
        capacitance = lu_factor(np.eye(changed.size) + delta[:, None] * (z_k.T @ y), check_finite=False)

        def solve(rhs: np.ndarray) -> np.ndarray:
            x = self.solve(rhs)
            return x - y @ lu_solve(capacitance, delta[:, None] * (z_k.T @ x) if x.ndim > 1 else delta * (z_k.T @ x), check_finite=False)

        return solve


def _dense_columns(z_t: sp.csr_matrix, rows: np.ndarray) -> np.ndarray:
    """(V, k): the rows ``rows`` (k,) of the CSR matrix ``z_t`` (m, V) as dense columns (a CSR row cut
    and conversion cost several times as much)."""
    start, count = z_t.indptr[rows], np.diff(z_t.indptr)[rows]
    column = np.repeat(np.arange(rows.shape[0]), count)
    entry = _ranges(start, count)
    out = np.zeros((rows.shape[0], z_t.shape[1]))
    out[column, z_t.indices[entry]] = z_t.data[entry]
    return out.T


def indefinite_solve(matrix: sp.csc_matrix):
    """solve(rhs (v,) or (v, k)) with a symmetric indefinite matrix (v, v): QDLDL's LDL^T, checked.

    QDLDL (approximate minimum degree, then an LDL^T with its pivots on the diagonal) factored
    and solved the two-pole's block matrices of the ankle stances in 0.55-0.77x SuperLU's time
    (symmetric mode, threshold pivoting), with residuals at round-off (relative <= 5e-15 against
    SuperLU's 2e-15; ``benchmarks/bench_factorisations.py``). The
    block is not quasi-definite (the bulge term's local compliance is below its strength, so its
    diagonal block is indefinite where springs are in contact), so no pivot order is guaranteed
    stable; each solve is therefore checked, and past a normwise backward error of v times the
    unit round-off (the bound of a factorisation without element growth) the matrix is factored by
    SuperLU with threshold pivoting instead. A zero pivot (QDLDL refuses it) goes the same way.
    """
    import qdldl  # a core dependency, imported where the two-pole needs it

    n = matrix.shape[0]
    try:
        ldl = qdldl.Solver(matrix)
    except RuntimeError:  # a zero pivot
        ldl = None
    norm = float(np.abs(matrix).sum(axis=1).max()) if n else 0.0  # ||A||_inf
    pivoted = []

    def superlu():
        if not pivoted:
            try:
                pivoted.append(splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}).solve)
            except RuntimeError as error:  # SuperLU's "singular matrix"
                raise SolverError(f"the coupled thin-layer matrix is singular ({error})") from None
        return pivoted[0]

    def solve(rhs: np.ndarray) -> np.ndarray:
        if ldl is None or pivoted:
            return superlu()(rhs)
        columns = rhs.reshape(n, -1)
        x = np.column_stack([ldl.solve(b) for b in columns.T])  # QDLDL solves one vector at a time
        backward = np.abs(matrix @ x - columns).max(axis=0) / (norm * np.abs(x).max(axis=0) + np.abs(columns).max(axis=0))
        if not np.all(backward <= n * np.finfo(float).eps):  # also NaN
            return superlu()(rhs)
        return x.reshape(rhs.shape)

    return solve


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
        in place of Q (``CoarseSpace``): only the springs of nonzero weight are summed.
        """
        if self.coarse is None:
            return self.h.data + self.pattern.sum_at_slots(self.sigma * self.weight**2 * spring_weight / 9.0)
        pair, spring = self.coarse.pairs_of(np.flatnonzero(spring_weight))
        added = self.sigma * self.weight[spring] ** 2 * spring_weight[spring] * self.coarse.pair_product[pair]
        return self.h.data + np.bincount(self.coarse.pair_slot[pair], weights=added, minlength=self.h.data.shape[0])


@dataclass(frozen=True)
class LayerCompliance:
    """w = C f on a set of springs: C = diag(local) + sum_i sigma_i Z_i^T H_i^-1 Z_i (module docstring).

    ``local`` is c_loc / A in mm/N. No term means no coupling (independent springs). The contact
    solve works on the terms' vertex fields stacked, z = (sigma H)^-1 Z f with Z = [Z_1; Z_2 ...]
    and sigma H = diag(sigma_i H_i), so that w = local f + Z^T z.
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
        """Past this many changed weights a refactorisation is cheaper than the Woodbury correction."""
        return LOW_RANK_MAX if len(self.terms) == 1 else LOW_RANK_MAX_INDEFINITE

    def factored_set(self) -> np.ndarray | None:
        """(m,) bool: the springs in contact (positive weight) in the kept factor, if it was
        built on these operators; None otherwise. A first contact set for the active-set
        iteration that needs no factorisation."""
        base = None if self.reuse is None else self.reuse.get("base")
        if base is None or not base.matches(self._operator_key(), self.local_mm_per_n.shape[0]):
            return None
        return base.weight > 0.0

    def _operator_key(self) -> tuple:
        """What the factored matrix depends on besides the spring weights: each term's sign, its
        pattern (by identity), H's data and the weights c_nl of Z."""
        return tuple((t.sigma, id(t.pattern), t.h.data, t.weight) for t in self.terms)

    def _factorise(self, spring_weight: np.ndarray):
        """Factor of sigma H + Z diag(spring_weight) Z^T: solve(rhs).

        One term: sigma (H + sigma Z diag(x) Z^T), SPD (module docstring), by the pattern's
        banded Cholesky. Two: the block matrix is symmetric but indefinite (its blocks' signs
        differ), factored by QDLDL's LDL^T, checked (``indefinite_solve``). Its pattern follows the
        contact set (the two terms' fields are coupled only through springs in contact), so the
        ordering is found anew each time: one pattern holding every spring of the layer would keep
        it, but on the gap law's 30k-spring layer (the whole surface) its fill made each
        factorisation 2x slower (217 ms against 111 ms), and one growing with the springs in
        contact over a time point was found again at 56 of 76 factorisations (docs/method.md).
        """
        if len(self.terms) == 1:
            term = self.terms[0]
            solve = term.pattern.factorise(term.coupled_data(spring_weight))
            return solve if term.sigma > 0 else (lambda rhs: -solve(rhs))
        return indefinite_solve((self._signed_block + self.z @ (self.z_t.multiply(spring_weight[:, None])).tocsc()).tocsc())

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
    symbol: str = "pade",
    smoothing_resolution: float = 0.0,
) -> LayerCompliance:
    """The thin-layer compliance on the springs ``cells`` (indices) with local thickness (m,) mm.

    ``edge_at_cells``: the layer ends at the boundary of ``cells`` (a free lateral face there),
    rather than going on beyond them with a natural cut. ``symbol``: a name of LAYER_SYMBOLS.
    ``smoothing_resolution`` > 0: each term is solved on a coarse space (module docstring, "Coarse
    smoothing space") of this many cells per smoothing length sqrt(b) h (at the median h), where
    those cells are at least COARSE_MIN_SPRINGS springs across; 0: on the springs' vertices."""
    h = np.broadcast_to(np.asarray(thickness_mm, float), cells.shape)
    # The gap laws' layer over the whole surface has the same cells and thickness at every time
    # point of a run: its compliance is built once (kept with the cells' operator patterns).
    key = (np.asarray(cells).tobytes(), h.tobytes(), youngs_modulus_mpa, poissons_ratio, edge_at_cells, symbol, smoothing_resolution)
    kept = mesh.memo.get("layer")
    if kept is not None and kept[0] == key:
        return kept[1]
    g = youngs_modulus_mpa / (2.0 * (1.0 + poissons_ratio))
    h_over_g = h / g
    model = LAYER_SYMBOLS[symbol](poissons_ratio)
    coarse_cells = smoothing_resolution > 0.0 and cells.size > 0
    if coarse_cells:  # (medians over the cells: only where a coarse space may be built)
        spring_mm, median_h = float(np.sqrt(2.0 * np.median(mesh.area_mm2[cells]))), float(np.median(h))
    terms = []
    for strength, b, dirichlet in zip(model.strengths, model.screenings, model.dirichlet):
        # S = (c_nl - div(b h^2 c_nl grad))^-1 c_nl (module docstring, variable thickness).
        c_nl = np.broadcast_to(abs(strength) * h_over_g, cells.shape)
        smoothing, pattern = mesh.smoothing_operators(cells, c_nl, b * h * h * c_nl, edge_at_cells, dirichlet)
        size_mm = np.sqrt(b) * median_h / smoothing_resolution if coarse_cells else 0.0
        coarse = mesh.coarse_space(cells, edge_at_cells, dirichlet, size_mm) if size_mm > 0.0 and size_mm >= COARSE_MIN_SPRINGS * spring_mm else None
        q = pattern.q if coarse is None else coarse.pattern.q  # Z^T = diag(c_nl) Q: Q's rows scaled, no sparse product
        z_t = sp.csr_matrix((q.data * np.repeat(c_nl, np.diff(q.indptr)), q.indices, q.indptr), shape=q.shape)
        if coarse is not None:
            smoothing, pattern = coarse.operator(smoothing), coarse.pattern
        terms.append(SmoothingTerm(float(np.sign(strength)), z_t, smoothing, c_nl, pattern, coarse))
    layer = LayerCompliance(model.local * h_over_g / mesh.area_mm2[cells], tuple(terms), mesh.memo.setdefault("factor", {}))
    mesh.memo["layer"] = (key, layer)
    return layer
