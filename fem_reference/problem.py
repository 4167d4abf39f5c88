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

from dataclasses import dataclass, field
from typing import Any, Literal, Sequence

import numpy as np

from geometries.errors import SolverError
from geometries.fe_solids import BONDED_TAG, CONTACT_TAG
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


Obstacle = RigidPlane | RigidCylinder | RigidSurface


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
    "auto": "iterative from 20,000 unknowns (fem_reference.sizing.ITERATIVE_FROM_DOFS) or where the "
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
        if not isinstance(self.obstacle, (RigidPlane, RigidCylinder, RigidSurface)):
            raise TypeError("obstacle must be a RigidPlane, RigidCylinder or RigidSurface")
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
        return "TH" if self.poissons_ratio >= 0.49 else "P2"

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
