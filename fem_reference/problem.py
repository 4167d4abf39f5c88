"""State of one static FE contact solve (docs/method.md#6-the-fe-reference-and-its-discrete-twins), independent of scene files.

Only numpy/scipy here: importing this module must not import dolfinx. Units mm, N, MPa.

Conventions
-----------
* The elastic body (cartilage) is bonded on the facets tagged ``bonded_tag`` to a rigid bone.
  The bone moves by a rigid translation ``t``; the bonded face is displaced by exactly ``t``.
* ``force_n`` is the force applied to that bone. At equilibrium the body transmits it through the
  contact to the rigid obstacle, so the *contact force* reported is the force the body exerts on
  the obstacle, ``F_c = integral of p * (-nu) dA`` with ``nu`` the obstacle normal, and
  ``F_c = force_n`` along the free translation directions.
* Obstacle normals ``nu`` point out of the obstacle, towards the body. The gap of a body point x is
  its signed distance from the obstacle measured along ``nu`` (positive = separated). Small
  strain: the contact condition is ``gap(x) + u(x) . nu(x) >= 0`` with gap and normal evaluated at
  the undeformed position.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal, Sequence

import numpy as np

from geometries.errors import SolverError
from geometries.fe_solids import (
    BONDED_TAG, CONTACT_TAG, FIXED_BONDED_TAG, FIXED_CONTACT_TAG, FIXED_VOLUME_TAG, vertex_normals,
)
from geometries.triangle_kernels import closest_points_on_triangles


ElementName = Literal["auto", "P1", "P2", "TH"]

#: Facet tags of the mesh builders of :mod:`fem_reference.meshes`: bonded, contact and free are
#: those of :mod:`geometries.fe_solids` (BONDED_TAG, CONTACT_TAG, FREE_TAG); the rollers add:
TAG_ROLLER_X = 4  # face with zero x-displacement (symmetry plane / roller)
TAG_ROLLER_Y = 5
TAG_ROLLER_Z = 6

AXES = {"x": 0, "y": 1, "z": 2}


class FEConvergenceError(SolverError):
    """The FE contact solve did not converge; carries the SNES reason and the last residual."""

    def __init__(self, message: str, *, reason: str = "", residual_norm: float = float("nan"),
                 iterations: int = 0) -> None:
        self.reason = reason
        self.residual_norm = float(residual_norm)
        self.iterations = int(iterations)
        super().__init__(
            f"{message} (reason: {reason or 'n/a'}; last residual norm {self.residual_norm:.3e}; "
            f"{self.iterations} iterations)")


def _unit(v: Sequence[float], name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    n = float(np.linalg.norm(a))
    if n == 0.0:
        raise ValueError(f"{name} must be non-zero")
    return a / n


def _point(v: Sequence[float], name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


# --------------------------------------------------------------------------------------------
# Obstacles
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RigidPlane:
    """Rigid plane through ``point_mm`` with unit ``normal`` pointing towards the body."""

    point_mm: tuple[float, float, float]
    normal: tuple[float, float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "point_mm", tuple(_point(self.point_mm, "RigidPlane.point_mm")))
        object.__setattr__(self, "normal", tuple(_unit(self.normal, "RigidPlane.normal")))

    def gap_and_normal(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed gap (n,) and obstacle normal (n, 3) at ``points`` (n, 3)."""
        x = np.asarray(points, dtype=float).reshape(-1, 3)
        n = np.asarray(self.normal)
        return (x - np.asarray(self.point_mm)) @ n, np.broadcast_to(n, x.shape).copy()

    def axis(self) -> int | None:
        """Index of the coordinate axis the normal is parallel to, or None."""
        n = np.abs(np.asarray(self.normal))
        i = int(np.argmax(n))
        return i if abs(n[i] - 1.0) < 1e-12 else None


@dataclass(frozen=True)
class RigidCylinder:
    """Rigid circular cylinder (infinite along its axis); the body lies outside it.

    Gap = distance from the axis minus the radius, measured radially (the obstacle normal is the
    radial direction away from the axis).
    """

    axis_point_mm: tuple[float, float, float]
    axis_direction: tuple[float, float, float]
    radius_mm: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis_point_mm",
                           tuple(_point(self.axis_point_mm, "RigidCylinder.axis_point_mm")))
        object.__setattr__(self, "axis_direction",
                           tuple(_unit(self.axis_direction, "RigidCylinder.axis_direction")))
        if not (self.radius_mm > 0.0):
            raise ValueError(f"RigidCylinder.radius_mm must be > 0, got {self.radius_mm!r}")

    def gap_and_normal(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(points, dtype=float).reshape(-1, 3) - np.asarray(self.axis_point_mm)
        a = np.asarray(self.axis_direction)
        r = x - np.outer(x @ a, a)
        rn = np.linalg.norm(r, axis=1)
        if np.any(rn == 0.0):
            raise ValueError("a contact point lies on the RigidCylinder axis")
        return rn - self.radius_mm, r / rn[:, None]


@dataclass(frozen=True, eq=False)
class RigidSurface:
    """Rigid triangulated surface. Triangle normals (right-hand rule on ``triangles``, or the
    reverse with ``flip_normals``) must point out of the obstacle, towards the body.

    The gap of a point is its signed distance, along the normal of the nearest triangle, from
    that triangle's plane (nearest = smallest exact point-triangle distance among the
    ``candidates`` triangles whose centroids are nearest, found with a scipy cKDTree).
    """

    vertices_mm: np.ndarray
    triangles: np.ndarray
    flip_normals: bool = False
    candidates: int = 8

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices_mm, dtype=float)
        t = np.asarray(self.triangles)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise ValueError("RigidSurface.vertices_mm must be a finite (n, 3) array")
        if t.ndim != 2 or t.shape[1] != 3 or t.size == 0:
            raise ValueError("RigidSurface.triangles must be a non-empty (m, 3) integer array")
        if t.min() < 0 or t.max() >= len(v):
            raise ValueError("RigidSurface.triangles index outside vertices_mm")
        t = t.astype(np.int64)
        if self.flip_normals:
            t = t[:, ::-1]
        nrm = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        area2 = np.linalg.norm(nrm, axis=1)
        if np.any(area2 <= 1e-14 * max(1.0, float(np.ptp(v)) ** 2)):
            raise ValueError("RigidSurface has degenerate (zero-area) triangles")
        object.__setattr__(self, "vertices_mm", v)
        object.__setattr__(self, "triangles", t)
        object.__setattr__(self, "_normals", nrm / area2[:, None])
        object.__setattr__(self, "_tree", None)

    def gap_and_normal(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from scipy.spatial import cKDTree

        x = np.asarray(points, dtype=float).reshape(-1, 3)
        v, t = self.vertices_mm, self.triangles
        if self._tree is None:  # type: ignore[attr-defined]
            object.__setattr__(self, "_tree", cKDTree(v[t].mean(axis=1)))
        k = int(min(max(1, self.candidates), len(t)))
        _, idx = self._tree.query(x, k=k)  # type: ignore[attr-defined]
        idx = np.asarray(idx).reshape(len(x), k)
        best = np.full(len(x), np.inf)
        best_tri = np.zeros(len(x), dtype=np.int64)
        for j in range(k):
            tri = idx[:, j]
            d2, _ = closest_points_on_triangles(x, v[t[tri, 0]], v[t[tri, 1]], v[t[tri, 2]])
            better = d2 < best - 1e-15
            best[better] = d2[better]
            best_tri[better] = tri[better]
        n = self._normals[best_tri]  # type: ignore[attr-defined]
        gap = np.einsum("ij,ij->i", x - v[t[best_tri, 0]], n)
        return gap, n


def _plane_strain_compliance(youngs_modulus_mpa: float, poissons_ratio: float) -> float:
    """(1 - nu^2) / E (1/MPa): a body's share of the contact compliance (Hertz's 1 / E*)."""
    return (1.0 - float(poissons_ratio) ** 2) / float(youngs_modulus_mpa)


@dataclass(frozen=True, eq=False)
class DeformableCounterpart:
    """F as a second elastic layer in the same mesh, in frictionless contact with M's
    (docs/method.md#two-deformable-layers; solved by :mod:`fem_reference.two_body`).

    Its contact face (``contact_tag``) is M's (the problem's ``contact_tag``) carried onto F: the
    same triangles, and the pairing is point to point and fixed in the reference configuration
    (small sliding): each node Y of M's contact face (vertex, and for P2 edge midpoint) faces the
    node Z of F's with the same place in the shared triangulation. The gap and the contact normal
    are measured along the normal of the interface the two faces close onto: the unit vector
    along w n_F - (1 - w) n_M (n_F, n_M the faces' outward normals at Z and Y; w = c_M / (c_M + c_F),
    c = (1 - nu^2) / E each body's contact compliance), i.e. F's normal when F is rigid, M's when M
    is, their mean for equal materials; it points out of F, towards M (the rigid obstacles'
    convention), gap = (Y - Z) . nu. F is bonded to its rigid bone on ``bonded_tag`` (held
    fixed); its tetrahedra are tagged ``cell_tag`` (every other cell is M's).

    ``mobile_points_mm`` (n, 3) M's contact-face vertices and ``mobile_normals`` (n, 3) its outward
    normals there, ``fixed_points_mm`` (n, 3) the vertices of F they face and ``fixed_normals``
    (n, 3) F's outward normals, ``triangles`` (m, 3) the shared connectivity (indices into the n
    points); F's material, and M's (``mobile_*``, None: F's; :class:`FEContactProblem` sets it to its
    own). :meth:`from_solid` reads the geometry from a paired :class:`geometries.fe_solids.FESolid`.
    ``follow_slip``: :func:`fem_reference.contact.solve_contact` re-pairs each node of M with the
    point of F its relative tangential displacement carried it to (:meth:`slid`) and solves again,
    until the pairing stops moving (the deformed configuration's pairing, to first order).
    """

    mobile_points_mm: np.ndarray
    mobile_normals: np.ndarray
    fixed_points_mm: np.ndarray
    fixed_normals: np.ndarray
    triangles: np.ndarray
    youngs_modulus_mpa: float
    poissons_ratio: float
    mobile_youngs_modulus_mpa: float | None = None
    mobile_poissons_ratio: float | None = None
    bonded_tag: int = FIXED_BONDED_TAG
    contact_tag: int = FIXED_CONTACT_TAG
    cell_tag: int = FIXED_VOLUME_TAG
    follow_slip: bool = False
    #: per node of M's contact face (vertices, then edge midpoints): the triangle of F's face it
    #: faces after sliding and the barycentric weights there (-1: its own partner node); :meth:`slid`
    slide_triangle: np.ndarray | None = field(default=None, repr=False)
    slide_weights: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        y, z = (np.asarray(a, dtype=float).reshape(-1, 3) for a in (self.mobile_points_mm, self.fixed_points_mm))
        n_m, n_f = (np.asarray(a, dtype=float).reshape(-1, 3) for a in (self.mobile_normals, self.fixed_normals))
        t = np.asarray(self.triangles, dtype=np.int64).reshape(-1, 3)
        if not (len(y) == len(z) == len(n_m) == len(n_f)) or not len(t) or t.min() < 0 or t.max() >= len(y):
            raise ValueError("DeformableCounterpart: the points and normals need one row per point and triangles "
                             "indices into them")
        for e, nu, who in ((self.youngs_modulus_mpa, self.poissons_ratio, "F"),
                           (self.mobile_youngs_modulus_mpa, self.mobile_poissons_ratio, "M")):
            if (e is None) != (nu is None) or (e is not None and not (float(e) > 0.0 and np.isfinite(e) and -1.0 < float(nu) < 0.5)):
                raise ValueError(f"DeformableCounterpart: {who}'s E = {e!r} MPa, nu = {nu!r} (need E > 0, -1 < nu < 0.5)")
        unit_m = n_m / np.linalg.norm(n_m, axis=1)[:, None]
        unit_f = n_f / np.linalg.norm(n_f, axis=1)[:, None]
        c_f = _plane_strain_compliance(self.youngs_modulus_mpa, self.poissons_ratio)
        c_m = c_f if self.mobile_youngs_modulus_mpa is None else _plane_strain_compliance(
            self.mobile_youngs_modulus_mpa, self.mobile_poissons_ratio)
        weight = c_m / (c_m + c_f)
        nu_v = weight * unit_f - (1.0 - weight) * unit_m
        length = np.linalg.norm(nu_v, axis=1)
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(z)) and np.all(length > 1e-6)):
            raise ValueError("DeformableCounterpart: non-finite points, or faces whose normals do not face each other")
        nu_v /= length[:, None]
        # the P1 and P2 nodes of the shared triangulation: vertices, then edge midpoints
        edges = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
        mid_n = nu_v[edges[:, 0]] + nu_v[edges[:, 1]]
        partner = np.vstack([z, 0.5 * (z[edges[:, 0]] + z[edges[:, 1]])])
        facing = partner.copy()
        if self.slide_triangle is not None:
            moved = np.asarray(self.slide_triangle) >= 0
            corners = z[t[np.asarray(self.slide_triangle)[moved]]]  # (k, 3 corners, 3)
            facing[moved] = np.einsum("kc,kcx->kx", np.asarray(self.slide_weights)[moved], corners)
        object.__setattr__(self, "_edges", edges)
        object.__setattr__(self, "_nodes_mobile", np.vstack([y, 0.5 * (y[edges[:, 0]] + y[edges[:, 1]])]))
        object.__setattr__(self, "_nodes_partner", partner)
        object.__setattr__(self, "_nodes_fixed", facing)
        object.__setattr__(self, "_nodes_normal", np.vstack([nu_v, mid_n / np.linalg.norm(mid_n, axis=1)[:, None]]))
        object.__setattr__(self, "_tree", None)

    @classmethod
    def from_solid(cls, solid: Any, youngs_modulus_mpa: float, poissons_ratio: float, **mobile: float) -> "DeformableCounterpart":
        """The counterpart of a paired solid (:func:`geometries.fe_solids.pair_solids`): M's
        contact face, the partners of its points, both faces' area-weighted vertex normals.
        ``mobile``: M's ``mobile_youngs_modulus_mpa`` and ``mobile_poissons_ratio``."""
        tris = solid.faces(CONTACT_TAG)
        used = np.unique(tris)
        remap = np.full(len(solid.points_mm), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        partner = solid.partner[used]
        on_face = np.full(len(solid.points_mm), -1, dtype=np.int64)
        on_face[partner] = np.arange(used.size)
        mobile_normals = vertex_normals(solid.points_mm[used], remap[tris])
        fixed_normals = vertex_normals(solid.points_mm[partner], on_face[solid.faces(FIXED_CONTACT_TAG)])
        return cls(solid.points_mm[used], mobile_normals, solid.points_mm[partner], fixed_normals, remap[tris],
                   youngs_modulus_mpa, poissons_ratio, **mobile)

    def with_mobile_material(self, youngs_modulus_mpa: float, poissons_ratio: float) -> "DeformableCounterpart":
        """This counterpart facing M of the given material (ValueError if it was built for another)."""
        if self.mobile_youngs_modulus_mpa is not None and not np.allclose(
                [self.mobile_youngs_modulus_mpa, self.mobile_poissons_ratio], [youngs_modulus_mpa, poissons_ratio], rtol=1e-12, atol=0.0):
            raise ValueError(f"the DeformableCounterpart was built for M of E = {self.mobile_youngs_modulus_mpa} MPa, "
                             f"nu = {self.mobile_poissons_ratio}, the problem's M has E = {youngs_modulus_mpa}, nu = {poissons_ratio}")
        return replace(self, mobile_youngs_modulus_mpa=float(youngs_modulus_mpa), mobile_poissons_ratio=float(poissons_ratio))

    def _nodes(self, points: np.ndarray) -> np.ndarray:
        from scipy.spatial import cKDTree

        if self._tree is None:  # type: ignore[attr-defined]
            object.__setattr__(self, "_tree", cKDTree(self._nodes_mobile))  # type: ignore[attr-defined]
        x = np.asarray(points, dtype=float).reshape(-1, 3)
        dist, idx = self._tree.query(x)  # type: ignore[attr-defined]
        size = float(np.ptp(self._nodes_mobile, axis=0).max()) or 1.0  # type: ignore[attr-defined]
        if len(x) and float(dist.max()) > 1e-8 * size:
            raise ValueError(f"DeformableCounterpart: {int(np.sum(dist > 1e-8 * size))} points are not nodes of M's "
                             f"paired contact face (farthest {float(dist.max()):.3g} mm): the mesh does not match the pairing")
        return idx

    def gap_and_normal(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Initial gap (n,) and contact normal (n, 3), out of F, at nodes of M's contact face (n, 3)."""
        i = self._nodes(points)
        y, z, nu = self._nodes_mobile[i], self._nodes_fixed[i], self._nodes_normal[i]  # type: ignore[attr-defined]
        return np.einsum("ij,ij->i", y - z, nu), nu

    def facing_points(self, points: np.ndarray) -> np.ndarray:
        """The point of F's contact face (n, 3) paired with each node of M's (n, 3)."""
        return self._nodes_fixed[self._nodes(points)]  # type: ignore[attr-defined]

    def stencil(self, points: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
        """F's displacement at the points paired with nodes of M's face (n, 3), as weights on F's
        nodes of a Lagrange field of ``degree`` (1 or 2): the nodes' coordinates (n, k, 3) and the
        weights (n, k), k = 3 or 6 (zero weights pad a node paired with a node)."""
        i = self._nodes(points)
        z = np.asarray(self.fixed_points_mm, dtype=float)
        k = 3 if degree == 1 else 6
        coords = np.repeat(self._nodes_partner[i][:, None, :], k, axis=1)  # type: ignore[attr-defined]
        weights = np.zeros((len(i), k))
        weights[:, 0] = 1.0
        tri = np.full(len(i), -1) if self.slide_triangle is None else np.asarray(self.slide_triangle)[i]
        moved = tri >= 0
        if moved.any():
            corners = z[np.asarray(self.triangles)[tri[moved]]]
            lam = np.asarray(self.slide_weights)[i[moved]]
            if degree == 1:
                coords[moved], weights[moved] = corners, lam
            else:  # P2 on the triangle: corners lam (2 lam - 1), edge midpoints 4 lam_a lam_b
                pairs = ((0, 1), (1, 2), (2, 0))
                mids = np.stack([0.5 * (corners[:, a] + corners[:, b]) for a, b in pairs], axis=1)
                coords[moved] = np.concatenate([corners, mids], axis=1)
                weights[moved] = np.column_stack([lam * (2.0 * lam - 1.0)] + [4.0 * lam[:, a] * lam[:, b] for a, b in pairs])
        return coords, weights

    def slid(self, points: np.ndarray, slip_mm: np.ndarray) -> "DeformableCounterpart":
        """This counterpart with the nodes of M's face at ``points`` (n, 3) paired instead with the
        point of F's face their slip (n, 3) carries their partner node to (the closest point of F's
        face to partner + slip): the pairing of the deformed configuration, to first order."""
        from scipy.spatial import cKDTree

        i = self._nodes(points)
        z = np.asarray(self.fixed_points_mm, dtype=float)
        tris = np.asarray(self.triangles)
        target = self._nodes_partner[i] + np.asarray(slip_mm, dtype=float).reshape(-1, 3)  # type: ignore[attr-defined]
        candidates = min(12, len(tris))
        _, near = cKDTree(z[tris].mean(axis=1)).query(target, k=candidates)
        near = np.asarray(near).reshape(len(target), candidates)
        d2, lam = closest_points_on_triangles(target[:, None, :], z[tris[near, 0]], z[tris[near, 1]], z[tris[near, 2]])
        best = np.argmin(d2, axis=1)
        n_nodes = len(self._nodes_mobile)  # type: ignore[attr-defined]
        triangle = np.full(n_nodes, -1) if self.slide_triangle is None else np.asarray(self.slide_triangle).copy()
        weights = np.zeros((n_nodes, 3)) if self.slide_weights is None else np.asarray(self.slide_weights, dtype=float).copy()
        triangle[i] = near[np.arange(len(i)), best]
        weights[i] = lam[np.arange(len(i)), best]
        return replace(self, slide_triangle=triangle, slide_weights=weights)

    def lame(self) -> tuple[float, float]:
        """F's (lambda, mu) in MPa."""
        e, nu = float(self.youngs_modulus_mpa), float(self.poissons_ratio)
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))


Obstacle = RigidPlane | RigidCylinder | RigidSurface | DeformableCounterpart


# --------------------------------------------------------------------------------------------
# Problem description
# --------------------------------------------------------------------------------------------


@dataclass
class FEMesh:
    """A dolfinx mesh with its facet tags (and optional cell tags). Held as ``Any`` so that this
    module does not import dolfinx."""

    mesh: Any
    facet_tags: Any
    cell_tags: Any = None


@dataclass(frozen=True)
class Roller:
    """Facets tagged ``tag`` have zero displacement along coordinate ``axis`` (0, 1, 2 or
    'x', 'y', 'z'): a frictionless roller or a symmetry plane normal to that axis."""

    tag: int
    axis: int | str

    def __post_init__(self) -> None:
        ax = AXES.get(self.axis, self.axis) if isinstance(self.axis, str) else self.axis
        if ax not in (0, 1, 2):
            raise ValueError(f"Roller.axis must be 0, 1, 2 or x, y, z; got {self.axis!r}")
        object.__setattr__(self, "axis", int(ax))


@dataclass(frozen=True)
class NitscheParameters:
    """Chouly-Hild Nitsche contact: gamma = gamma0 * (lambda + 2 mu) / h, with 2 mu in place of
    lambda + 2 mu for Taylor-Hood (whose stress's displacement part is 2 mu eps(u)).

    h = "height": the height of the cell over its contact facet, 3 * volume / facet area (what
    the discrete trace inequality needs; robust on anisotropic cells) or "diameter": the cell
    diameter. theta = -1 (skew-symmetric, stable for any gamma0 > 0; the default) or 1
    (symmetric Jacobian; needs gamma0 large enough for coercivity: with too small a gamma0 on
    flat cells the inactive contact surface develops spurious strains) or 0."""

    theta: float = -1.0
    gamma0: float = 10.0
    h: str = "height"

    def __post_init__(self) -> None:
        if self.h not in ("height", "diameter"):
            raise ValueError(f"Nitsche h must be 'height' or 'diameter', got {self.h!r}")
        if self.theta not in (-1.0, 0.0, 1.0):
            raise ValueError(f"Nitsche theta must be -1, 0 or 1, got {self.theta!r}")
        if not (self.gamma0 > 0.0):
            raise ValueError(f"Nitsche gamma0 must be > 0, got {self.gamma0!r}")


#: Inner linear solves of the bordered Newton (``SolverOptions.linear_solver``, ``[fe]
#: linear_solver``, ``edem fe --linear-solver``); docs/method.md, section 6.
LINEAR_SOLVERS = {
    "auto": "iterative from 20,000 unknowns for P2 and Taylor-Hood (fem_reference.sizing.ITERATIVE_FROM_DOFS) or where the "
            "LU's memory estimate (x2) does not fit, direct below",
    "direct": "MUMPS LU of the Jacobian",
    "iterative": "Krylov to an Eisenstat-Walker forcing term: P2 GMRES (CG for Nitsche theta = 1) + "
                 "P2 -> P1 p-multigrid (SOR, GAMG with the rigid-body near-nullspace on P1); P1 "
                 "the same with GAMG alone; Taylor-Hood GMRES + Schur-complement field split (the "
                 "p-multigrid on the displacement, the pressure mass matrix scaled by 1/mu + "
                 "1/lambda on the pressure)",
}


@dataclass(frozen=True)
class SolverOptions:
    """Newton (PETSc SNES) settings. Tolerances are on the residual norm (N)."""

    max_iterations: int = 50
    rtol: float = 1e-10
    atol_rel_to_load: float = 1e-11  # absolute tolerance = this * |force_n|
    linesearch: str = "basic"  # "basic" (full semi-smooth Newton steps) or "bt"
    force_balance_rtol: float = 1e-6  # a converged solve must balance the load to this
    petsc_options: tuple[tuple[str, str], ...] = ()  # extra SNES options (without prefix)
    monitor: bool = False  # print the Newton residuals and translations (rank 0)
    linear_solver: str = "auto"  # a key of LINEAR_SOLVERS: the inner linear solve

    def __post_init__(self) -> None:
        if self.linear_solver not in LINEAR_SOLVERS:
            raise ValueError(f"linear_solver must be one of {', '.join(LINEAR_SOLVERS)}, "
                             f"got {self.linear_solver!r}")


@dataclass
class FEContactProblem:
    """One static, force-controlled, frictionless FE contact solve.

    mesh: :class:`FEMesh` or a callable ``comm -> FEMesh`` building one.
    element: "P1", "P2", "TH" (Taylor-Hood P2-P1 u-p mixed) or "auto" = TH when
      nu >= 0.49, else P2.
    free_dofs: rigid translations of the bone that are unknown. ``None``: one, along the load
      direction. Or a sequence of axis names ("x", "y", "z") or of direction vectors. The other
      translations are fixed at zero (their reaction is reported as ``constraint_force_n``).
    free_rotations: small rigid rotations of the bone about ``reference_point_mm`` that are
      unknown (``None``/empty: none; else axis names or axis vectors). A small rotation q moves
      the bonded face by q x (x - G), a field without strain, so testing the weak form with it
      leaves the moment of the contact force about G: each free rotation adds the moment
      balance ``a . (M_c - moment_nmm) = 0``. The other rotations are fixed at zero.
    rollers: zero normal displacement on tagged faces (symmetry planes, confining walls).
    initial_translation_mm / initial_rotation_rad / initial_field: warm start (e.g. the
      previous time point; ``initial_field`` = ``fields["ut_owned"]`` of a solve on the same mesh
      object and element); default: a rigid approach along the load (see
      ``ContactSetup.initial_translation``), no rotation, u~ = 0.
    """

    mesh: Any
    youngs_modulus_mpa: float
    poissons_ratio: float
    obstacle: Obstacle
    force_n: Sequence[float]
    bonded_tag: int = BONDED_TAG
    contact_tag: int = CONTACT_TAG
    rollers: tuple[Roller, ...] = ()
    element: ElementName = "auto"
    free_dofs: Any = None
    nitsche: NitscheParameters = field(default_factory=NitscheParameters)
    solver: SolverOptions = field(default_factory=SolverOptions)
    quadrature_degree: int | None = None  # cells; default 2 (exact stiffness for P1/P2/TH)
    contact_quadrature_degree: int | None = None  # contact facets; default 2 * degree + 2
    initial_penetration_mm: float | None = None  # beyond first touch; default: Winkler estimate
    strain_warning: float = 0.10
    free_rotations: Any = None
    moment_nmm: Sequence[float] = (0.0, 0.0, 0.0)
    reference_point_mm: Sequence[float] = (0.0, 0.0, 0.0)
    initial_translation_mm: Sequence[float] | None = None
    initial_rotation_rad: Sequence[float] | None = None
    initial_field: Any = None  # owned values of the elastic part u~ (fields["ut_owned"] of a
    # previous solve on the same mesh and element): warm start of the displacement field
    # A Kelvin-Voigt time step (fem_reference.viscoelastic): the unknown is v = u + tau du/dt and
    # the contact condition acts on u = (v + h) / c0, i.e. gap' = gap_scale * gap + h . nu with
    # h = gap_history (a dolfinx Function in the vector Lagrange space of the displacement degree)
    gap_scale: float = 1.0
    gap_history: Any = None
    # A time scheme's own bulk terms in place of the elastic ones (fem_reference.biphasic_contact): a
    # callable (ContactSetup, solution, test function) -> an object with ``displacement`` and
    # ``test_displacement`` (the displacement parts, UFL), ``stress_u`` and ``stress_v`` (the total
    # stress of each, whose normal part Nitsche's terms take) and ``residual(contact_pressure)`` (the
    # bulk part of the residual form, given the contact pressure as a UFL expression). None: elastic
    bulk_form: Any = None

    def __post_init__(self) -> None:
        e, nu = float(self.youngs_modulus_mpa), float(self.poissons_ratio)
        if not (e > 0.0 and np.isfinite(e)):
            raise ValueError(f"youngs_modulus_mpa must be > 0, got {self.youngs_modulus_mpa!r}")
        if not (-1.0 < nu < 0.5):
            raise ValueError(f"poissons_ratio must be in (-1, 0.5), got {self.poissons_ratio!r}")
        f = np.asarray(self.force_n, dtype=float).reshape(-1)
        if f.shape != (3,) or not np.all(np.isfinite(f)) or np.linalg.norm(f) == 0.0:
            raise ValueError("force_n must be 3 finite numbers, not all zero; "
                             f"got {self.force_n!r}")
        self.force_n = f
        if self.element not in ("auto", "P1", "P2", "TH"):
            raise ValueError(f"element must be auto, P1, P2 or TH; got {self.element!r}")
        if not isinstance(self.obstacle, (RigidPlane, RigidCylinder, RigidSurface, DeformableCounterpart)):
            raise TypeError("obstacle must be a RigidPlane, RigidCylinder, RigidSurface or DeformableCounterpart")
        if isinstance(self.obstacle, DeformableCounterpart):
            self.obstacle = self.obstacle.with_mobile_material(e, nu)
        self.rollers = tuple(r if isinstance(r, Roller) else Roller(*r) for r in self.rollers)
        self.moment_nmm = _point(self.moment_nmm, "moment_nmm")
        self.reference_point_mm = _point(self.reference_point_mm, "reference_point_mm")
        if self.rollers and len(self.free_rotation_axes()):
            raise ValueError("free rotations move the bonded face along every axis: they cannot "
                             "be combined with rollers")
        for name in ("initial_translation_mm", "initial_rotation_rad"):
            if getattr(self, name) is not None:
                setattr(self, name, _point(getattr(self, name), name))

    # ---- derived quantities (pure numpy) ----
    def resolved_element(self) -> str:
        if self.element != "auto":
            return self.element
        nu = max(self.poissons_ratio, getattr(self.obstacle, "poissons_ratio", self.poissons_ratio))
        return "TH" if nu >= 0.49 else "P2"

    def lame(self) -> tuple[float, float]:
        """(lambda, mu) in MPa."""
        e, nu = self.youngs_modulus_mpa, self.poissons_ratio
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))

    def free_directions(self) -> np.ndarray:
        """Orthonormal rows (k, 3) spanning the free bone translations."""
        # with free rotations a load along fixed translations only may still be balanced by a
        # moment: the rotation equations then carry the problem
        return resolve_free_directions(self.free_dofs, self.force_n, self.rollers,
                                       require_load=not len(self.free_rotation_axes()))

    def free_rotation_axes(self) -> np.ndarray:
        """Orthonormal rows (k_r, 3) spanning the free bone rotations (may be empty)."""
        return resolve_rotation_axes(self.free_rotations)


def _axis_rows(items: Any, what: str) -> np.ndarray:
    """Orthonormal rows from axis names ("x", "y", "z") or vectors (0 to 3 of them)."""
    items = [items] if isinstance(items, str) else list(items)
    rows = []
    for it in items:
        if isinstance(it, str):
            if it.lower() not in AXES:
                raise ValueError(f"{what}: unknown axis {it!r} (expected x, y, z)")
            d = np.zeros(3)
            d[AXES[it.lower()]] = 1.0
            rows.append(d)
        else:
            rows.append(_unit(it, f"{what} direction"))
    d = np.array(rows, dtype=float).reshape(-1, 3)
    if len(d) > 3:
        raise ValueError(f"{what} must name at most 3 axes")
    if len(d) == 0:
        return d
    q, r = np.linalg.qr(d.T)
    if np.min(np.abs(np.diag(r))) < 1e-10:
        raise ValueError(f"{what} directions are linearly dependent")
    # keep the user's directions when they are already orthonormal (axis names)
    if np.allclose(d @ d.T, np.eye(len(d)), atol=1e-12):
        q = d.T
    return q.T.copy()


def resolve_rotation_axes(free_rotations: Any) -> np.ndarray:
    """Orthonormal rows (k_r, 3) of the free rotation axes; (0, 3) for None."""
    if free_rotations is None:
        return np.zeros((0, 3))
    return _axis_rows(free_rotations, "free_rotations")


def resolve_free_directions(free_dofs: Any, force_n: np.ndarray,
                            rollers: Sequence[Roller] = (), *,
                            require_load: bool = True) -> np.ndarray:
    f = np.asarray(force_n, dtype=float)
    if free_dofs is None:
        d = (f / np.linalg.norm(f)).reshape(1, 3)
    else:
        d = _axis_rows(free_dofs, "free_dofs")
        if len(d) == 0:
            raise ValueError("free_dofs must name 1 to 3 translations")
    if require_load and np.linalg.norm(d @ f) < 1e-12 * np.linalg.norm(f):
        raise ValueError("the load has no component along the free translations")
    for r_ in rollers:
        if np.any(np.abs(d[:, r_.axis]) > 1e-12):
            raise ValueError(
                f"a free translation moves the bonded face along axis {r_.axis}, which the roller "
                f"on tag {r_.tag} fixes; fix that translation or drop the roller")
    return d


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------

AREA_DEFINITION_NITSCHE = (
    "integral over the contact-tagged facets of the indicator [p > 1e-8 * max p] evaluated at the "
    "contact quadrature points (p = Nitsche positive-part pressure)")
AREA_DEFINITION_VI = (
    "sum of the lumped nodal areas (integral of the P1 hat function over the contact facets) of "
    "the contact-surface vertices with positive contact reaction")


@dataclass
class FEContactResult:
    """Outcome of one FE contact solve. Vectors in mm / N; pressures in MPa."""

    bone_displacement_mm: np.ndarray  # (3,) rigid translation of the bonded face
    free_directions: np.ndarray  # (k, 3)
    contact_points_mm: np.ndarray  # (n, 3) contact-surface vertices (all ranks gathered)
    contact_pressure_mpa: np.ndarray  # (n,) nodal pressure (lumped L2 projection onto P1)
    peak_pressure_mpa: float
    mean_pressure_mpa: float  # integral of p / contact area
    contact_area_mm2: float
    contact_area_definition: str
    contact_force_n: np.ndarray  # (3,) force exerted by the body on the obstacle
    applied_force_n: np.ndarray  # (3,)
    force_residual_n: float  # |P_free (contact_force - applied)|
    constraint_force_n: np.ndarray  # (3,) part of (contact_force - applied) taken by fixed dofs
    n_dofs: int
    newton_iterations: int
    converged_reason: str
    wall_time_s: float
    max_nominal_strain: float  # max |principal strain| at cell midpoints
    element: str
    method: str  # "nitsche" or "vi"
    outer_iterations: int = 0  # VI path: secant steps on the translation
    warnings: list[str] = field(default_factory=list)
    linear_solver: str = "direct"  # the inner solve used: "direct" or "iterative" (LINEAR_SOLVERS)
    krylov_iterations: int = 0  # iterative path: inner Krylov iterations summed over all solves
    krylov_iterations_per_step: list[int] = field(default_factory=list)  # iterative path: per Newton step
    # free rotations (empty without them): small rotation vector of the bone about G, the moment
    # of the contact force about G and |P_rot (M_c - moment)|
    rotation_axes: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    bone_rotation_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact_moment_nmm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    moment_residual_nmm: float = 0.0
    fields: Any = field(default=None, repr=False)  # dolfinx objects for post-processing

    @property
    def relative_force_residual(self) -> float:
        return self.force_residual_n / float(np.linalg.norm(self.applied_force_n))

    def summary(self) -> dict[str, Any]:
        """JSON-ready numbers (summary keys of docs/result-format.md where they apply)."""
        return {
            "method": f"fe-{self.method}",
            "element": self.element,
            "n_dofs": int(self.n_dofs),
            "wall_time_s": float(self.wall_time_s),
            "peak_pressure_mpa": float(self.peak_pressure_mpa),
            "mean_pressure_mpa": float(self.mean_pressure_mpa),
            "max_contact_area_mm2": float(self.contact_area_mm2),
            "contact_area_definition": self.contact_area_definition,
            "final_displacement_mm": [float(v) for v in self.bone_displacement_mm],
            "contact_force_n": [float(v) for v in self.contact_force_n],
            "max_force_residual_n": float(self.force_residual_n),
            "newton_iterations": int(self.newton_iterations),
            "max_nominal_strain": float(self.max_nominal_strain),
            "warnings": list(self.warnings),
        }
