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
Largest relative error against the exact C for kh <= 1 (kh <= 2), see ``pade_error_bound``:
nu 0: 3.0 % (22 %, the independent springs' own error); 0.1: 1.4 %; 0.2: 0.7 %; 0.3: 1.0 % (12 %);
0.42: 0.24 % (6.9 %); 0.45: 0.12 %; 0.49: 0.79 % (2.3 %); 0.499: 1.0 % (1.5 %).
The independent springs (C = h/E') are off by 29 % at nu 0.42 and 98 % at nu 0.499 for kh <= 1.

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
the smoothed field vanishes (S p = 0, Dirichlet), the Pade form of the thin-layer free-edge
condition p = 0 (for e -> 0 and a plate in full contact it gives the squeeze-film paraboloid
(3 G d / 2 h^3)(a^2 - x^2) plus an O(h^2/a^2) edge term; a no-flux edge would confine the
incompressible layer and make it rigid). Where the contact solve cuts the surface to a band
around the candidates (``edem.thin_layer_contact``), the layer goes on, and the cut is natural.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

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


def pade_compliance(kh: np.ndarray, poissons_ratio: float) -> np.ndarray:
    """C G / h of the [1/1] Pade model, dimensionless."""
    e, a, b = pade_coefficients(poissons_ratio)
    x = np.asarray(kh, float) ** 2
    return (e + a * x) / (1.0 + b * x)


def pade_error_bound(poissons_ratio: float, max_kh: float = 1.0) -> float:
    """Largest relative error of the Pade model against the exact compliance over 0 < kh <= max_kh."""
    kh = np.linspace(1e-3, max_kh, 2001)
    return float(np.max(np.abs(pade_compliance(kh, poissons_ratio) / exact_layer_compliance(kh, poissons_ratio) - 1.0)))


def operator_factors(poissons_ratio: float, shear_modulus_mpa: float, thickness_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(c_loc mm/MPa, c_nl mm/MPa, sigma, b) of w = c_loc p + sigma c_nl S p, per spring (module docstring)."""
    e, a, b = pade_coefficients(poissons_ratio)
    _, c1, _ = taylor_coefficients(poissons_ratio)
    h_over_g = np.asarray(thickness_mm, float) / shear_modulus_mpa
    if b == 0.0 or abs(c1) <= 1e-12 * e * b:
        return h_over_g * e, np.zeros_like(h_over_g), 0.0, 0.0
    return h_over_g * a / b, h_over_g * abs(c1) / b, -float(np.sign(c1)), b


# --------------------------------------------------------------------------- surface operators


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

    @staticmethod
    def from_corners(triangles: np.ndarray, corners_mm: np.ndarray) -> "SurfaceMesh":
        """From the vertex indices (n, 3) and the corner coordinates (n, 3, 3) in mm of each triangle."""
        out = np.empty(triangles.shape)
        area = 0.5 * np.linalg.norm(np.cross(corners_mm[:, 1] - corners_mm[:, 0], corners_mm[:, 2] - corners_mm[:, 0]), axis=1)
        for i in range(3):  # the three corners of every triangle at once
            u = corners_mm[:, (i + 1) % 3] - corners_mm[:, i]
            v = corners_mm[:, (i + 2) % 3] - corners_mm[:, i]
            out[:, i] = np.einsum("ij,ij->i", u, v) / np.maximum(2.0 * area, 1e-300)
        tri = np.asarray(triangles, np.int64)
        n = tri.shape[0]
        incidence = sp.csr_matrix((np.ones(3 * n), (np.repeat(np.arange(n), 3), tri.ravel())))
        edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        unique, count = np.unique(edges, axis=0, return_counts=True)
        free = np.zeros(incidence.shape[1], bool)
        free[unique[count == 1].ravel()] = True  # an edge of one triangle only
        return SurfaceMesh(tri, area, out, incidence, free)

    def neighbourhood(self, cells: np.ndarray, width_mm: float) -> np.ndarray:
        """Triangles within about ``width_mm`` of the triangles ``cells`` (bool mask, (n,)).

        Grown ring by ring through shared vertices; a ring is about one triangle size sqrt(2 A) wide.
        """
        incidence, incidence_t = self.incidence, self.incidence.T.tocsr()
        mask = np.zeros(self.triangles.shape[0], bool)
        mask[cells] = True
        size = float(np.sqrt(2.0 * self.area_mm2[mask]).mean()) if np.any(mask) else 1.0
        for _ in range(int(np.ceil(width_mm / max(size, 1e-12)))):
            grown = incidence @ (incidence_t @ mask.astype(float)) > 0
            if np.array_equal(grown, mask):
                break
            mask = grown
        return mask

    @staticmethod
    def from_surface(vertices_mm: np.ndarray, triangles: np.ndarray) -> "SurfaceMesh":
        return SurfaceMesh.from_corners(triangles, vertices_mm[triangles])

    def smoothing_operators(self, cells: np.ndarray, mass_weight: np.ndarray, stiffness_weight: np.ndarray) -> tuple[sp.csc_matrix, sp.csr_matrix]:
        """P1 operators on the triangles ``cells`` (indices, m): (H, Q).

        H = M + K (v, v): the mass M = Q^T diag(A mass_weight) Q plus the cotangent stiffness K
        with each triangle weighted by ``stiffness_weight`` (m,) (natural boundary), in one pass;
        Q (m, v): triangle value = mean of its corners. Vertices are renumbered to those the
        cells use; those on the surface's free edge are left out (the smoothed field vanishes
        there, module docstring), the rest of the subset's boundary is natural.
        """
        tri = self.triangles[cells]
        vertices, local = np.unique(tri, return_inverse=True)
        local = local.reshape(tri.shape)
        n_v, m = vertices.shape[0], tri.shape[0]
        # Mass: A m / 9 for every ordered pair of corners of a triangle (Q^T diag(A m) Q).
        pair_rows = np.repeat(local, 3, axis=1).ravel()
        pair_cols = np.tile(local, (1, 3)).ravel()
        pair_vals = np.repeat(self.area_mm2[cells] * np.asarray(mass_weight, float) / 9.0, 9)
        # Stiffness: the edge opposite corner i (corners i+1, i+2) carries w cot_i / 2.
        a = np.concatenate([local[:, (i + 1) % 3] for i in range(3)])
        b = np.concatenate([local[:, (i + 2) % 3] for i in range(3)])
        half = 0.5 * (self.cotangents[cells] * np.asarray(stiffness_weight, float)[:, None]).T.ravel()
        rows = np.concatenate([pair_rows, a, b, a, b])
        cols = np.concatenate([pair_cols, b, a, a, b])
        vals = np.concatenate([pair_vals, -half, -half, half, half])
        smoothing = sp.csc_matrix((vals, (rows, cols)), shape=(n_v, n_v))
        q = sp.csr_matrix((np.full(3 * m, 1.0 / 3.0), (np.repeat(np.arange(m), 3), local.ravel())), shape=(m, n_v))
        keep = ~self.free_edge_vertex[vertices]
        if not np.all(keep):
            smoothing, q = smoothing[keep][:, keep].tocsc(), q[:, keep].tocsr()
        return smoothing, q


@dataclass(frozen=True)
class LayerCompliance:
    """w = C f on a set of springs: C = diag(local) + sigma Z^T H^-1 Z (module docstring).

    ``local`` is c_loc / A in mm/N; Z (v, m) in mm/MPa; H (v, v) in mm^3/MPa.
    sigma = 0 means no coupling (independent springs, Z empty).
    """

    local_mm_per_n: np.ndarray  # (m,)
    z: sp.csr_matrix  # (v, m)
    h: sp.csc_matrix  # (v, v)
    sigma: float

    @property
    def coupled(self) -> bool:
        return self.sigma != 0.0

    def deflection(self, force_n: np.ndarray) -> np.ndarray:
        """Surface deflection w (m,) in mm under spring forces f (m,) in N."""
        w = self.local_mm_per_n * force_n
        if self.coupled:
            w = w + self.sigma * (self.z.T @ spsolve(self.h, self.z @ force_n))
        return w


def layer_compliance(
    mesh: SurfaceMesh,
    cells: np.ndarray,
    thickness_mm: np.ndarray,
    youngs_modulus_mpa: float,
    poissons_ratio: float,
) -> LayerCompliance:
    """The Pade thin-layer compliance on the springs ``cells`` (indices) with local thickness (m,) mm."""
    g = youngs_modulus_mpa / (2.0 * (1.0 + poissons_ratio))
    h = np.broadcast_to(np.asarray(thickness_mm, float), cells.shape)
    area = mesh.area_mm2[cells]
    c_loc, c_nl, sigma, b = operator_factors(poissons_ratio, g, h)
    if sigma == 0.0:
        return LayerCompliance(c_loc / area, sp.csr_matrix((0, cells.shape[0])), sp.csc_matrix((0, 0)), 0.0)
    # S = (c_nl - div(b h^2 c_nl grad))^-1 c_nl (module docstring, variable thickness).
    smoothing, q = mesh.smoothing_operators(cells, c_nl, b * h * h * c_nl)
    z = (q.T @ sp.diags(c_nl)).tocsr()
    return LayerCompliance(c_loc / area, z, smoothing, sigma)
