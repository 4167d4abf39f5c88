"""Force-controlled frictionless FE contact of a bonded elastic body against a rigid obstacle.

Small-strain linear elasticity (P1, P2 or Taylor-Hood P2-P1 u-p), unilateral frictionless
contact by Nitsche's method (Chouly-Hild form), and the rigid bone translation as extra unknowns
of the same Newton loop (:func:`solve_contact`). A variational-inequality cross-check
(:func:`solve_contact_vi`, PETSc ``vinewtonrsls``, P1, plane obstacle with a coordinate-axis
normal) solves displacement-controlled problems inside a secant iteration on the translation.

Formulation (see :mod:`fem_reference.problem` for the sign conventions). The displacement is
split as ``u = u~ + sum_j t_j E_j`` where ``E_j`` is the constant field equal to the free
direction ``e_j`` and ``u~ = 0`` on the bonded face (and on the roller components). A constant
field has no strain, so testing the weak form with ``E_j`` leaves only the contact term:
``F(u; E_j) = e_j . F_c`` with ``F_c`` the force on the obstacle. The extra equations are thus
exactly the force balance ``e_j . (F_c - force_n) = 0``. Newton solves the bordered system

    [ A    K ] [du~]   [R~]          A = dR~/du~ (bonded/roller rows = identity)
    [ G^T  H ] [dt ] = [r ],         K_j = dR~/dt_j, G_j = dr_j/du~, H = dr/dt

with PETSc SNES (newtonls) through a shell matrix and an exact block-elimination
preconditioner (one MUMPS factorisation of A per iteration, k + 1 back-substitutions; past the
LU's memory, k + 1 preconditioned Krylov solves instead: :func:`_krylov_amg`,
:func:`_krylov_fieldsplit`).

Heavy imports (dolfinx, petsc4py, ufl, basix) happen inside the functions.
"""

from __future__ import annotations

import itertools
import time
from typing import Any

import numpy as np

from .problem import (
    AREA_DEFINITION_NITSCHE,
    AREA_DEFINITION_VI,
    FEContactProblem,
    FEContactResult,
    FEConvergenceError,
    FEMesh,
    RigidCylinder,
    RigidPlane,
    RigidSurface,
)
from .progress import SolveProgress

_counter = itertools.count()


def _fe_modules() -> dict[str, Any]:
    """Import the FE stack in the order the wheel requires."""
    import dolfinx_solver  # noqa: F401  (must precede dolfinx / petsc4py)
    import basix.ufl
    import dolfinx
    import dolfinx.fem
    import dolfinx.fem.petsc
    import dolfinx.la
    import dolfinx.mesh
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    return {"dolfinx": dolfinx, "fem": dolfinx.fem, "fem_petsc": dolfinx.fem.petsc,
            "la": dolfinx.la, "ufl": ufl, "basix_ufl": basix.ufl, "MPI": MPI, "PETSc": PETSc}


def _snes_reason_name(PETSc: Any, reason: int) -> str:
    for name in dir(PETSc.SNES.ConvergedReason):
        if not name.startswith("_") and getattr(PETSc.SNES.ConvergedReason, name) == reason:
            if name.startswith(("CONVERGED", "DIVERGED")) or name == "ITERATING":
                return name
    return str(reason)


def materialize_mesh(problem: FEContactProblem, comm: Any) -> FEMesh:
    """The problem's mesh: an :class:`FEMesh`, or built by calling ``problem.mesh(comm)``."""
    src = problem.mesh
    if isinstance(src, FEMesh):
        return src
    if callable(src):
        built = src(comm)
        if isinstance(built, FEMesh):
            return built
        if isinstance(built, tuple) and len(built) in (2, 3):
            # (mesh, tags...) in any order of facet / cell tags, told apart by their dimension
            mesh, tags = built[0], [t for t in built[1:] if t is not None]
            tdim = mesh.topology.dim
            facet = [t for t in tags if t.dim == tdim - 1]
            cell = [t for t in tags if t.dim == tdim]
            if len(facet) == 1:
                return FEMesh(mesh, facet[0], cell[0] if cell else None)
        raise TypeError("the mesh callable must return an FEMesh or a tuple of a mesh and its "
                        "facet tags (and optionally cell tags)")
    raise TypeError("FEContactProblem.mesh must be an FEMesh or a callable comm -> FEMesh")


# --------------------------------------------------------------------------------------------
# Shared set-up
# --------------------------------------------------------------------------------------------


class _Setup:
    """Spaces, boundary conditions and UFL pieces shared by the Nitsche and VI paths."""

    def __init__(self, problem: FEContactProblem, comm: Any, element: str) -> None:
        m = self.m = _fe_modules()
        fem, ufl = m["fem"], m["ufl"]
        self.problem = problem
        data = materialize_mesh(problem, comm)
        self.mesh = mesh = data.mesh
        self.comm = mesh.comm
        self.facet_tags = data.facet_tags
        if self.facet_tags is None:
            raise ValueError("the FE mesh needs facet tags (bonded and contact faces)")
        self.tdim = mesh.topology.dim
        if self.tdim != 3 or mesh.geometry.dim != 3:
            raise ValueError("fem_reference solves 3D problems (use a thin slice for plane strain)")
        self.fdim = self.tdim - 1
        mesh.topology.create_connectivity(self.fdim, self.tdim)
        self.element = element
        self.degree = 1 if element == "P1" else 2
        self.bonded_facets = self._facets(problem.bonded_tag, "bonded")
        self.contact_facets = self._facets(problem.contact_tag, "contact")

        if element == "TH":
            bu = m["basix_ufl"]
            cell = mesh.basix_cell()
            mixed = bu.mixed_element([bu.element("Lagrange", cell, 2, shape=(3,)),
                                      bu.element("Lagrange", cell, 1)])
            self.V = fem.functionspace(mesh, mixed)
            self.Vu = self.V.sub(0)
        else:
            self.V = fem.functionspace(mesh, ("Lagrange", self.degree, (3,)))
            self.Vu = self.V
        im = self.V.dofmap.index_map
        self.n_owned = im.size_local * self.V.dofmap.index_map_bs
        self.n_global = im.size_global * self.V.dofmap.index_map_bs

        lam, mu = problem.lame()
        self.lam = fem.Constant(mesh, float(lam))
        self.mu = fem.Constant(mesh, float(mu))
        self.dirs = problem.free_directions()  # (k_t, 3)
        self.rot = problem.free_rotation_axes()  # (k_r, 3), about the reference point G
        self.kt = len(self.dirs)
        self.k = self.kt + len(self.rot)
        self.load = np.asarray(problem.force_n, dtype=float)
        self.moment = np.asarray(problem.moment_nmm, dtype=float)
        self.ref_point = np.asarray(problem.reference_point_mm, dtype=float)
        # generalised load of the rigid unknowns: e_j . F, then a_j . M (about G)
        self.gen_load = np.concatenate([self.dirs @ self.load, self.rot @ self.moment])

        qd = problem.quadrature_degree if problem.quadrature_degree is not None else 2
        qc = (problem.contact_quadrature_degree if problem.contact_quadrature_degree is not None
              else 2 * self.degree + 2)
        self.dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": qd})
        self.ds = ufl.Measure("ds", domain=mesh, subdomain_data=self.facet_tags,
                              metadata={"quadrature_degree": qc})
        self.ds_c = self.ds(problem.contact_tag)

        # Dirichlet conditions on u~: bonded face (all components), rollers (one component)
        if element == "TH":
            V0, _ = self.Vu.collapse()
            bdofs = fem.locate_dofs_topological((self.Vu, V0), self.fdim, self.bonded_facets)
            self.bcs = [fem.dirichletbc(fem.Function(V0), bdofs, self.Vu)]
        else:
            bdofs = fem.locate_dofs_topological(self.Vu, self.fdim, self.bonded_facets)
            self.bcs = [fem.dirichletbc(np.zeros(3, dtype=np.float64), bdofs, self.Vu)]
        self.bc_bonded_dofs = bdofs
        for r in problem.rollers:
            facets = self._facets(r.tag, f"roller (axis {r.axis})")
            sub = self.Vu.sub(r.axis)
            dofs = fem.locate_dofs_topological(sub, self.fdim, facets)
            self.bcs.append(fem.dirichletbc(np.float64(0.0), dofs, sub))
        owned, allc = [], []
        for bc in self.bcs:
            idx, first_ghost = bc.dof_indices()
            owned.append(np.asarray(idx[:first_ghost]))
            allc.append(np.asarray(idx))
        self.cons_owned = np.unique(np.concatenate(owned)).astype(np.int64)
        self.cons_all = np.unique(np.concatenate(allc)).astype(np.int64)

    def _facets(self, tag: int, what: str) -> np.ndarray:
        facets = self.facet_tags.find(tag)
        n = self.comm.allreduce(int(np.sum(facets < self.mesh.topology.index_map(self.fdim)
                                              .size_local)), op=self.m["MPI"].SUM)
        if n == 0:
            raise ValueError(f"no facets tagged {tag} ({what} face) in the FE mesh")
        return facets

    # ---- kinematics / material ----
    def eps(self, w: Any) -> Any:
        ufl = self.m["ufl"]
        return ufl.sym(ufl.grad(w))

    def sigma(self, w: Any, pr: Any = None) -> Any:
        ufl = self.m["ufl"]
        I = ufl.Identity(3)
        if pr is None:
            return 2.0 * self.mu * self.eps(w) + self.lam * ufl.tr(self.eps(w)) * I
        return 2.0 * self.mu * self.eps(w) - pr * I

    def constant_field(self, direction: np.ndarray) -> Any:
        """Function of V equal to ``direction`` everywhere (pressure part zero for TH)."""
        d = np.asarray(direction, dtype=np.float64)
        return self._vector_function(lambda x: np.tile(d.reshape(3, 1), (1, x.shape[1])))

    def rotation_field(self, axis: np.ndarray) -> Any:
        """Function of V equal to the small rotation ``axis x (x - G)`` (pressure part zero for
        TH): linear, so exact in P1/P2, and strain-free."""
        a = np.asarray(axis, dtype=np.float64)
        g = self.ref_point
        return self._vector_function(lambda x: np.cross(a, (x - g.reshape(3, 1)).T).T)

    def _vector_function(self, values: Any) -> Any:
        """Function of V interpolating the vector field ``values(x)`` (its displacement part for TH)."""
        f = self.m["fem"].Function(self.V)
        (f.sub(0) if self.element == "TH" else f).interpolate(values)
        f.x.scatter_forward()
        return f

    def rigid_modes(self) -> list:
        """The fields of the rigid unknowns: free translations, then free rotations."""
        return ([self.constant_field(d) for d in self.dirs]
                + [self.rotation_field(a) for a in self.rot])

    # ---- contact-surface points ----
    def contact_points(self, degree: int) -> tuple[np.ndarray, np.ndarray, Any]:
        """(local dof indices, coordinates) of a scalar Lagrange space of ``degree`` on the
        contact facets (owned and ghost), and the space."""
        fem = self.m["fem"]
        Q = fem.functionspace(self.mesh, ("Lagrange", degree))
        dofs = fem.locate_dofs_topological(Q, self.fdim, self.contact_facets)
        return dofs, Q.tabulate_dof_coordinates()[dofs], Q

    def obstacle_ufl(self) -> tuple[Any, Any]:
        """(gap, unit obstacle normal) as UFL expressions on the contact surface; a Kelvin-Voigt
        step's shifted gap c0 gap + h . nu (:class:`FEContactProblem` ``gap_scale``, ``gap_history``)."""
        gap, nu = self._obstacle_ufl()
        p = self.problem
        if p.gap_history is None and p.gap_scale == 1.0:
            return gap, nu
        ufl = self.m["ufl"]
        shifted = float(p.gap_scale) * gap
        return (shifted if p.gap_history is None else shifted + ufl.dot(p.gap_history, nu)), nu

    def shifted_gap(self, dofs: np.ndarray, gap: np.ndarray, normal: np.ndarray,
                    degree: int | None = None) -> np.ndarray:
        """The gap of :meth:`obstacle_ufl` at the contact-surface dofs ``dofs`` of
        :meth:`contact_points` (``degree``; default the displacement's)."""
        p = self.problem
        if p.gap_history is None:
            return float(p.gap_scale) * gap
        h = p.gap_history
        if degree is not None and degree != self.degree:
            h = self.m["fem"].Function(self.m["fem"].functionspace(self.mesh, ("Lagrange", degree, (3,))))
            h.interpolate(p.gap_history)
        values = h.x.array.reshape(-1, 3)[dofs]
        return float(p.gap_scale) * gap + np.einsum("ij,ij->i", values, normal)

    def _obstacle_ufl(self) -> tuple[Any, Any]:
        fem, ufl = self.m["fem"], self.m["ufl"]
        obs = self.problem.obstacle
        x = ufl.SpatialCoordinate(self.mesh)
        if isinstance(obs, RigidPlane):
            nu = fem.Constant(self.mesh, np.asarray(obs.normal, dtype=np.float64))
            x0 = fem.Constant(self.mesh, np.asarray(obs.point_mm, dtype=np.float64))
            return ufl.dot(x - x0, nu), nu
        if isinstance(obs, RigidCylinder):
            c = fem.Constant(self.mesh, np.asarray(obs.axis_point_mm, dtype=np.float64))
            a = fem.Constant(self.mesh, np.asarray(obs.axis_direction, dtype=np.float64))
            d = x - c
            r = d - ufl.dot(d, a) * a
            rn = ufl.sqrt(ufl.dot(r, r))
            return rn - obs.radius_mm, r / rn
        if isinstance(obs, RigidSurface):
            # gap and normal interpolated at the contact-surface dofs of the displacement degree
            dofs, pts, Q = self.contact_points(self.degree)
            g, nrm = obs.gap_and_normal(pts)
            gf = fem.Function(Q)
            gf.x.array[dofs] = g
            Qv = fem.functionspace(self.mesh, ("Lagrange", self.degree, (3,)))
            nf = fem.Function(Qv)
            nf.x.array.reshape(-1, 3)[dofs] = nrm
            self._surface_fields = (gf, nf)
            return gf, nf / ufl.sqrt(ufl.dot(nf, nf))
        raise TypeError(f"unsupported obstacle {type(obs).__name__}")

    def initial_translation(self) -> tuple[np.ndarray, float, float]:
        """Starting rigid translation (3,) along the load; also the touch distance and the
        penetration beyond it.

        The touch distance is the translation along the load at which the first contact-surface
        dof reaches the obstacle. Unless ``initial_penetration_mm`` is given, the penetration is
        half that of a Winkler bed (springs E' / L per unit area, L = extent of the body along
        the load) carrying the load (:meth:`_winkler_penetration`). Newton steps are damped so
        that the penetration changes by at most a factor 4 per step
        (:meth:`_BorderedSystem.step_limit`).
        """
        fem, ufl, MPI = self.m["fem"], self.m["ufl"], self.m["MPI"]
        obs = self.problem.obstacle
        ehat = self.load / np.linalg.norm(self.load)
        dofs, pts, _ = self.contact_points(self.degree)
        g, nrm = obs.gap_and_normal(pts) if len(pts) else (np.zeros(0), np.zeros((0, 3)))
        g = self.shifted_gap(dofs, g, nrm)
        s = nrm @ ehat
        approaching = s < -1e-9
        t_loc = float(np.min(g[approaching] / -s[approaching])) if approaching.any() else np.inf
        t_touch = self.comm.allreduce(t_loc, op=MPI.MIN)
        if not np.isfinite(t_touch):
            raise FEConvergenceError(
                "the load does not move the contact surface towards the obstacle (no contact "
                "point has an obstacle normal opposing the load direction)", reason="NO_CONTACT")
        proj = self.mesh.geometry.x @ ehat
        length = (self.comm.allreduce(float(proj.max()), op=MPI.MAX)
                  - self.comm.allreduce(float(proj.min()), op=MPI.MIN))
        pen = self.problem.initial_penetration_mm
        if pen is None:
            pen = self._winkler_penetration(ehat, t_touch, length)
        return (t_touch + pen) * ehat, t_touch, float(pen)

    def _winkler_penetration(self, ehat: np.ndarray, t_touch: float, length: float) -> float:
        """Half the approach (beyond first touch) at which a Winkler bed of depth ``length``
        (springs E' / length per unit area on the P1 contact vertices, lumped areas) carries
        the load. Thin layers: close to the FE answer; thick bodies: the bed is too soft and
        half its approach is a fair start. (Tried against a fixed 1e-3 * mesh diagonal and a
        bed depth set by the patch width: same total Newton count over 14 Hertz / layer /
        tilted-load cases, within 10 %; this is the simplest.)"""
        fem, ufl, MPI = self.m["fem"], self.m["ufl"], self.m["MPI"]
        dofs, _, Q = self.contact_points(1)
        own = dofs[dofs < Q.dofmap.index_map.size_local]
        area = self.vector_owned(fem.form(ufl.TestFunction(Q) * self.ds_c))[own]
        g, nrm = self.problem.obstacle.gap_and_normal(Q.tabulate_dof_coordinates()[own])
        g = self.shifted_gap(own, g, nrm, 1)
        sn = nrm @ ehat
        ok = sn < -1e-9
        ti, wi = g[ok] / -sn[ok], area[ok] * sn[ok] ** 2
        lam, mu = self.problem.lame()
        k = (lam + 2.0 * mu) / length
        target = float(np.linalg.norm(self.load))

        def force(t: float) -> float:
            return k * self.comm.allreduce(float(np.sum(wi * np.clip(t - ti, 0.0, None))),
                                           op=MPI.SUM)

        lo, hi = t_touch, t_touch + 1e-6 * length
        for _ in range(200):
            if force(hi) >= target:
                break
            lo, hi = hi, t_touch + 2.0 * (hi - t_touch)
        else:
            return 1e-3 * length
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if force(mid) < target else (lo, mid)
        return 0.5 * (hi - t_touch)

    # ---- post-processing shared by both paths ----
    def max_principal_strain(self, u: Any) -> float:
        fem, MPI = self.m["fem"], self.m["MPI"]
        T = fem.functionspace(self.mesh, ("DG", 0, (3, 3)))
        ef = fem.Function(T)
        ef.interpolate(fem.Expression(self.eps(u), T.element.interpolation_points))
        ncl = self.mesh.topology.index_map(self.tdim).size_local
        vals = ef.x.array.reshape(-1, 3, 3)[:ncl]
        loc = float(np.abs(np.linalg.eigvalsh(vals)).max()) if ncl else 0.0
        return self.comm.allreduce(loc, op=MPI.MAX)

    def gather(self, arr: np.ndarray) -> np.ndarray:
        parts = self.comm.allgather(np.asarray(arr))
        return np.concatenate(parts, axis=0) if parts else np.asarray(arr)

    def scalar(self, form: Any) -> float:
        fem, MPI = self.m["fem"], self.m["MPI"]
        return self.comm.allreduce(float(fem.assemble_scalar(form)), op=MPI.SUM)

    def vector_owned(self, form: Any) -> np.ndarray:
        fem, la = self.m["fem"], self.m["la"]
        vec = fem.assemble_vector(form)
        vec.scatter_reverse(la.InsertMode.add)
        n = vec.index_map.size_local * vec.block_size
        return vec.array[:n].copy()

    def force_split(self, contact_force: np.ndarray) -> tuple[float, np.ndarray]:
        diff = contact_force - self.load
        free = self.dirs.T @ (self.dirs @ diff)
        return float(np.linalg.norm(free)), diff - free


# --------------------------------------------------------------------------------------------
# Nitsche + bordered Newton
# --------------------------------------------------------------------------------------------


def _use_iterative(s: "_Setup") -> bool:
    """Whether the inner solve is Krylov (see :data:`fem_reference.problem.LINEAR_SOLVERS`)."""
    from fem_reference.sizing import direct_fits

    choice = s.problem.solver.linear_solver
    return choice == "iterative" or (choice == "auto" and not direct_fits(s.n_global))


#: Relative tolerance of each inner Krylov solve, on the unpreconditioned residual (GMRES with
#: right preconditioning). Newton stops at 1e-10 of its first residual: an inner solve 1e-10
#: exact makes each step a Newton step up to a relative 1e-10, so Newton's last steps keep
#: reducing the residual by about that factor (inexact Newton) instead of stalling.
INNER_RTOL = 1e-10
#: Inner Krylov iterations before a solve is declared not converged.
INNER_MAX_IT = 1000
#: GMRES restart (PETSc's default is 30: with it and GAMG's defaults the 0.7 mm subject slab did
#: not converge in 2000 iterations). PETSc allocates the Krylov vectors as the iteration reaches
#: them: 60 iterations on 420k DOFs hold 0.2 GB.
GMRES_RESTART = 200

#: GAMG settings for the elastic block (PETSc options under the inner solver's prefix). Threshold:
#: drop graph edges below 5 % of the diagonal before aggregating, so that the thin slabs'
#: anisotropic P2 couplings give compact aggregates; 3 Chebyshev-Jacobi smoothing steps per
#: level. Measured on the subject-like ankle (1.4 mm, P2, 73k DOFs): 120-140 iterations per
#: inner solve with the PETSc defaults and GMRES(30) at 1e-12, about 60 with these.
GAMG_OPTIONS = {"pc_gamg_threshold": "0.05", "mg_levels_ksp_type": "chebyshev",
                "mg_levels_pc_type": "jacobi", "mg_levels_ksp_max_it": "3"}


def _rigid_body_modes(coords: np.ndarray, like: Any) -> list:
    """The six rigid-body motions at the displacement nodes ``coords`` (n, 3) (owned, in the order
    of ``like``'s blocks of three) as PETSc vectors: the near-nullspace GAMG builds its coarse
    spaces from (elasticity's kernel without supports)."""
    centred = coords - coords.mean(axis=0) if len(coords) else coords
    modes = []
    for j in range(6):
        field = np.zeros_like(centred)
        if j < 3:
            field[:, j] = 1.0
        else:  # rotation about axis j - 3: e x (x - c)
            field = np.cross(np.eye(3)[j - 3], centred)
        vec = like.duplicate()
        with vec as arr:
            arr[:] = field.reshape(-1)
        modes.append(vec)
    return modes


def _near_nullspace(s: "_Setup", coords: np.ndarray, like: Any) -> Any:
    """The rigid-body modes at ``coords`` as an orthonormal PETSc near-nullspace."""
    PETSc = s.m["PETSc"]
    modes = _rigid_body_modes(coords, like)
    for j, vec in enumerate(modes):  # Gram-Schmidt: a PETSc null space has an orthonormal basis
        for prev in modes[:j]:
            vec.axpy(-vec.dot(prev), prev)
        vec.normalize()
    return PETSc.NullSpace().create(vectors=modes, comm=s.comm)


def _set_inner_options(ksp: Any, options: dict[str, str]) -> list[str]:
    """Put ``options`` in the PETSc database under the inner solver's prefix and read them.
    They stay there until the solve ends (:func:`_destroy` removes the returned keys): the
    multigrid levels and the field-split blocks read theirs when the preconditioner is set up."""
    from petsc4py import PETSc

    db = PETSc.Options()
    keys = [f"{ksp.getOptionsPrefix()}{key}" for key in options]
    for key, val in zip(keys, options.values()):
        db[key] = val
    ksp.setFromOptions()
    return keys


def _krylov_amg(ksp: Any, A: Any, s: "_Setup") -> list[str]:
    """P1/P2: CG (symmetric Nitsche, theta = 1) or right-preconditioned GMRES with GAMG and the
    rigid-body near-nullspace on the blocked (3 per node) displacement."""
    nodes = s.V.dofmap.index_map.size_local
    vec, _ = A.createVecs()
    A.setNearNullSpace(_near_nullspace(s, s.V.tabulate_dof_coordinates()[:nodes], vec))
    vec.destroy()
    options = {"pc_type": "gamg", **GAMG_OPTIONS}
    if s.problem.nitsche.theta == 1.0:
        options["ksp_type"] = "cg"
    else:
        options.update(ksp_type="gmres", ksp_gmres_restart=str(GMRES_RESTART), ksp_pc_side="right")
    ksp.setTolerances(rtol=INNER_RTOL, atol=0.0, max_it=INNER_MAX_IT)
    return _set_inner_options(ksp, options)


def _krylov_fieldsplit(ksp: Any, s: "_Setup") -> tuple[list, list[str]]:
    """Taylor-Hood: right-preconditioned GMRES with a Schur-complement field split (u, p).

    Displacement block: one GAMG cycle with the rigid-body near-nullspace (its IS ordered node by
    node, block size 3); it holds the Nitsche contact terms in u. Pressure (Schur complement
    S = A_pp - A_pu A_uu^-1 A_up, negative definite): approximated by -(1/mu + 1/lambda) M_p,
    the pressure mass matrix scaled like the inverse shear stiffness plus the compressible term
    (-M_p / lambda is A_pp itself; div A_uu^-1 div^T is spectrally M_p / mu on inf-sup stable
    elements), one Jacobi sweep on it. Full factorisation (lower, Schur, upper).

    Returns the PETSc objects the solve keeps (index sets, the pressure matrix) and the option
    keys set, for :func:`_destroy`."""
    fem, ufl, PETSc = s.m["fem"], s.m["ufl"], s.m["PETSc"]
    offset = s.V.dofmap.index_map.local_range[0]  # mixed space: block size 1
    # collapse(): the subspace and, per cell type (one here), the parent dof of each of its dofs,
    # owned first; the displacement's unrolled node by node (3 i + component)
    V0, (u_map,) = s.V.sub(0).collapse()
    Q, (p_map,) = s.V.sub(1).collapse()
    nu_owned = V0.dofmap.index_map.size_local
    np_owned = Q.dofmap.index_map.size_local
    is_u = PETSc.IS().createGeneral((offset + u_map[: 3 * nu_owned]).astype(PETSc.IntType), comm=s.comm)
    is_u.setBlockSize(3)
    is_p = PETSc.IS().createGeneral((offset + p_map[:np_owned]).astype(PETSc.IntType), comm=s.comm)
    like = PETSc.Vec().createMPI((3 * nu_owned, PETSc.DECIDE), bsize=3, comm=s.comm)
    nsp = _near_nullspace(s, V0.tabulate_dof_coordinates()[:nu_owned], like)
    like.destroy()
    is_u.compose("nearnullspace", nsp)
    p, q = ufl.TrialFunction(Q), ufl.TestFunction(Q)
    scale = fem.Constant(s.mesh, -(1.0 / float(s.mu.value) + 1.0 / float(s.lam.value)))
    Mp = s.m["fem_petsc"].assemble_matrix(fem.form(scale * p * q * s.dx))
    Mp.assemble()
    pc = ksp.getPC()
    pc.setType("fieldsplit")
    pc.setFieldSplitIS(("u", is_u), ("p", is_p))
    pc.setFieldSplitType(PETSc.PC.CompositeType.SCHUR)
    pc.setFieldSplitSchurFactType(PETSc.PC.FieldSplitSchurFactType.FULL)
    pc.setFieldSplitSchurPreType(PETSc.PC.FieldSplitSchurPreType.USER, Mp)
    options = {"ksp_type": "gmres", "ksp_gmres_restart": str(GMRES_RESTART), "ksp_pc_side": "right",
               "fieldsplit_u_ksp_type": "preonly", "fieldsplit_u_pc_type": "gamg",
               **{f"fieldsplit_u_{k}": v for k, v in GAMG_OPTIONS.items()},
               "fieldsplit_p_ksp_type": "preonly", "fieldsplit_p_pc_type": "jacobi"}
    ksp.setTolerances(rtol=INNER_RTOL, atol=0.0, max_it=INNER_MAX_IT)
    return [is_u, is_p, nsp, Mp], _set_inner_options(ksp, options)


class _BorderedSystem:
    """Residual, Jacobian (shell) and exact block preconditioner of the bordered Newton system."""

    def __init__(self, s: _Setup, uh: Any, ut: Any, E: list, forms: dict, prefix: str) -> None:
        self.s = s
        self.uh, self.ut, self.E = uh, ut, E
        self.f = forms
        PETSc = s.m["PETSc"]
        self.PETSc = PETSc
        self.rank = s.comm.rank
        self.k = s.k
        self.no = s.n_owned
        self.Eo = [e.x.array[: self.no].copy() for e in E]
        self.Ea = [e.x.array.copy() for e in E]
        self.load_free = s.gen_load
        self.delta = np.zeros(self.k)
        self.A = s.m["fem_petsc"].create_matrix(forms["J"])
        self.A.setOptionsPrefix(f"{prefix}A_")
        self.ksp = PETSc.KSP().create(s.comm)
        self.ksp.setOptionsPrefix(f"{prefix}inner_")
        self.iterative = _use_iterative(s)
        self.krylov_iterations = 0
        self.keep: list = []  # PETSc objects of the preconditioner, destroyed with the system
        self.option_keys: list[str] = []  # its entries in the PETSc options database, likewise
        if not self.iterative:
            self.ksp.setType("preonly")
            pc = self.ksp.getPC()
            pc.setType("lu")
            pc.setFactorSolverType("mumps")
            self.ksp.setFromOptions()
        elif s.element == "TH":
            self.keep, self.option_keys = _krylov_fieldsplit(self.ksp, s)
        else:
            self.option_keys = _krylov_amg(self.ksp, self.A, s)
        self.wu, self.zu = self.A.createVecs()
        self.K = [np.zeros(self.no) for _ in range(self.k)]
        self.G = [np.zeros(self.no) for _ in range(self.k)]
        self.Xs = [np.zeros(self.no) for _ in range(self.k)]
        self.H = np.zeros((self.k, self.k))
        self.S = np.eye(self.k)
        self.S_ref: np.ndarray | None = None
        self.singular_steps = 0
        self.error: Exception | None = None
        self.limited_steps = 0
        self.ehat: np.ndarray | None = None  # set with t_touch to enable the step limit
        self.t_touch = 0.0

    # ---- helpers ----
    def dot(self, a: np.ndarray, b: np.ndarray) -> float:
        return self.s.comm.allreduce(float(np.dot(a, b)), op=self.s.m["MPI"].SUM)

    def split(self, X: Any) -> tuple[np.ndarray, np.ndarray]:
        xa = X.getArray(readonly=True)
        xu = np.array(xa[: self.no])
        xd = np.array(xa[self.no: self.no + self.k]) if self.rank == 0 else None
        return xu, self.s.comm.bcast(xd, root=0)

    def join(self, Y: Any, yu: np.ndarray, yd: np.ndarray) -> None:
        with Y as ya:  # writable local array; the vector state is bumped on exit
            ya[: self.no] = yu
            if self.rank == 0:
                ya[self.no: self.no + self.k] = yd

    def _load(self, rhs: np.ndarray) -> None:
        with self.wu as w:
            w[:] = rhs

    def solve_A(self, rhs: np.ndarray) -> np.ndarray:
        self._load(rhs)
        self.ksp.solve(self.wu, self.zu)
        if not self.iterative:
            return np.array(self.zu.getArray(readonly=True))
        self.krylov_iterations += self.ksp.getIterationNumber()
        if self.ksp.getConvergedReason() <= 0:
            raise FEConvergenceError(
                f"the inner Krylov solve ({self.ksp.getType()} + {self.ksp.getPC().getType()}) did not converge",
                reason=str(self.ksp.getConvergedReason()), residual_norm=self.ksp.getResidualNorm(),
                iterations=self.ksp.getIterationNumber())
        return np.array(self.zu.getArray(readonly=True))

    def set_state(self, X: Any) -> None:
        xu, xd = self.split(X)
        self.ut.x.array[: self.no] = xu
        self.ut.x.scatter_forward()
        self.ut.x.array[self.s.cons_all] = 0.0
        self.delta = xd
        arr = self.ut.x.array.copy()
        for j in range(self.k):
            arr += xd[j] * self.Ea[j]
        self.uh.x.array[:] = arr

    # ---- SNES callbacks ----
    def residual(self, snes: Any, X: Any, F: Any) -> None:
        try:
            self._residual(X, F)
        except Exception as exc:  # re-raised by solve_contact after SNES returns
            self.error = exc
            raise

    def jacobian(self, snes: Any, X: Any, J: Any, P: Any) -> None:
        try:
            self._jacobian(X, J)
        except Exception as exc:
            self.error = exc
            raise

    def _residual(self, X: Any, F: Any) -> None:
        self.set_state(X)
        b = self.s.vector_owned(self.f["F"])
        r = np.array([self.dot(self.Eo[j], b) for j in range(self.k)]) - self.load_free
        b[self.s.cons_owned] = self.ut.x.array[self.s.cons_owned]
        self.join(F, b, r)

    def _jacobian(self, X: Any, J: Any) -> None:
        s, fp = self.s, self.s.m["fem_petsc"]
        self.set_state(X)
        self.A.zeroEntries()
        fp.assemble_matrix(self.A, self.f["J"], bcs=s.bcs, diag=1.0)
        self.A.assemble()
        for j in range(self.k):
            self.K[j] = s.vector_owned(self.f["K"][j])
            self.K[j][s.cons_owned] = 0.0
            self.G[j] = s.vector_owned(self.f["G"][j])
            self.G[j][s.cons_owned] = 0.0
            for m_ in range(self.k):
                self.H[j, m_] = s.scalar(self.f["H"][j][m_])
        self.ksp.setOperators(self.A)
        self.ksp.setUp()
        for j in range(self.k):
            self.Xs[j] = self.solve_A(self.K[j])
        S = self.H - np.array([[self.dot(self.G[j], self.Xs[m_]) for m_ in range(self.k)]
                               for j in range(self.k)])
        # The Schur complement is the tangent contact stiffness of the free translations; it is
        # singular when an iterate has lost contact. Fall back on the last regular one.
        sv = np.linalg.svd(S, compute_uv=False)
        if self.S_ref is None:
            if sv.min() <= 1e-12 * max(sv.max(), 1e-300):
                raise FEConvergenceError(
                    "no contact stiffness along (a combination of) the free translations at the "
                    "initial state: either the contact surface does not touch the obstacle, or "
                    "frictionless contact cannot resist a free translation tangent to the "
                    "obstacle (fix that translation through free_dofs)", reason="NO_CONTACT")
            self.S_ref = S.copy()
        ref = np.linalg.svd(self.S_ref, compute_uv=False).max()
        if sv.min() <= 1e-8 * ref:
            self.singular_steps += 1
            S = self.S_ref.copy()
        else:
            self.S_ref = S.copy()
        self.S = S
        J.assemble()

    def mult(self, mat: Any, x: Any, y: Any) -> None:
        xu, xd = self.split(x)
        self._load(xu)
        self.A.mult(self.wu, self.zu)
        yu = np.array(self.zu.getArray(readonly=True))
        for j in range(self.k):
            yu += xd[j] * self.K[j]
        yd = np.array([self.dot(self.G[j], xu) for j in range(self.k)]) + self.H @ xd
        self.join(y, yu, yd)

    def apply(self, pc: Any, x: Any, y: Any) -> None:
        xu, xd = self.split(x)
        z0 = self.solve_A(xu)
        rhs = xd - np.array([self.dot(self.G[j], z0) for j in range(self.k)])
        dd = np.linalg.solve(self.S, rhs)
        yu = z0
        for j in range(self.k):
            yu = yu - dd[j] * self.Xs[j]
        alpha = self.step_limit(dd)
        if alpha < 1.0:
            yu, dd = alpha * yu, alpha * dd
            self.limited_steps += 1
        self.join(y, yu, dd)

    def step_limit(self, dd: np.ndarray) -> float:
        """Damping factor keeping the penetration beyond first touch (along the load) within a
        factor ``growth`` of the current one per Newton step (SNES steps X <- X - Y)."""
        if self.ehat is None:
            return 1.0
        growth = 4.0
        kt = self.s.kt
        pen = float(self.ehat @ (self.s.dirs.T @ self.delta[:kt])) - self.t_touch
        new = pen - float(self.ehat @ (self.s.dirs.T @ dd[:kt]))
        if pen <= 0.0 or new == pen:
            return 1.0
        if new > growth * pen:
            return (growth - 1.0) * pen / (new - pen)
        if new < pen / growth:
            return (pen / growth - pen) / (new - pen)
        return 1.0

    def setUp(self, pc: Any) -> None:  # noqa: N802 (petsc4py python-context API)
        pass


class _ShellContext:
    def __init__(self, system: _BorderedSystem) -> None:
        self.system = system

    def mult(self, mat: Any, x: Any, y: Any) -> None:
        self.system.mult(mat, x, y)


def solve_contact(problem: FEContactProblem, comm: Any = None, *,
                  keep_fields: bool = True, progress: SolveProgress | None = None) -> FEContactResult:
    """Solve ``problem`` by Nitsche contact with force control (bordered semi-smooth Newton).

    ``progress``: progress lines from inside the solve (:mod:`fem_reference.progress`); in
    parallel give one on every rank (rank 0 writes).

    Raises :class:`FEConvergenceError` when SNES does not converge or the converged solution
    does not balance the load to ``problem.solver.force_balance_rtol``.
    """
    t_start = time.perf_counter()
    m = _fe_modules()
    fem, ufl, PETSc, MPI = m["fem"], m["ufl"], m["PETSc"], m["MPI"]
    comm = MPI.COMM_WORLD if comm is None else comm
    element = problem.resolved_element()
    s = _Setup(problem, comm, element)
    warnings: list[str] = []
    if element == "P1" and problem.poissons_ratio >= 0.49:
        warnings.append(f"P1 elements lock at nu = {problem.poissons_ratio}: displacements are "
                        "underestimated; use TH or P2")

    uh = fem.Function(s.V, name="displacement")
    ut = fem.Function(s.V)
    w = ufl.TestFunction(s.V)
    dw = ufl.TrialFunction(s.V)
    E = s.rigid_modes()

    if element == "TH":
        u, p_ = ufl.split(uh)
        v, q = ufl.split(w)
        sig_u, sig_v = s.sigma(u, p_), s.sigma(v, q)
        a_int = (ufl.inner(2.0 * s.mu * s.eps(u), s.eps(v)) - p_ * ufl.div(v)
                 - q * (ufl.div(u) + p_ / s.lam)) * s.dx
    else:
        u, v = uh, w
        sig_u, sig_v = s.sigma(u), s.sigma(v)
        a_int = ufl.inner(sig_u, s.eps(v)) * s.dx

    gap, nu = s.obstacle_ufl()
    if problem.nitsche.h == "height":
        h = 3.0 * ufl.CellVolume(s.mesh) / ufl.FacetArea(s.mesh)
    else:
        h = ufl.CellDiameter(s.mesh)
    lam, mu = problem.lame()
    # A Kelvin-Voigt step (gap_scale c0) constrains u = (v + h) / c0: gamma (u . n - gap) is
    # (gamma / c0) (v . n - gap'), so a steady state solves the elastic discrete problem exactly
    gamma = fem.Constant(s.mesh, float(problem.nitsche.gamma0 * (lam + 2.0 * mu) / problem.gap_scale)) / h
    theta = fem.Constant(s.mesh, float(problem.nitsche.theta))
    sn_u = ufl.dot(ufl.dot(sig_u, nu), nu)
    sn_v = ufl.dot(ufl.dot(sig_v, nu), nu)
    un, vn = -ufl.dot(u, nu), -ufl.dot(v, nu)  # along the body's outward normal n = -nu
    pressure = ufl.max_value(0.0, gamma * (un - gap) - sn_u)
    F = (a_int - theta / gamma * sn_u * sn_v * s.ds_c - theta / gamma * pressure * sn_v * s.ds_c
         + pressure * vn * s.ds_c)

    FE = [ufl.replace(F, {w: e}) for e in E]
    forms = {
        "F": fem.form(F),
        "J": fem.form(ufl.derivative(F, uh, dw)),
        "K": [fem.form(ufl.derivative(F, uh, e)) for e in E],
        "G": [fem.form(ufl.derivative(fe, uh, w)) for fe in FE],
        "H": [[fem.form(ufl.derivative(fe, uh, e)) for e in E] for fe in FE],
    }

    prefix = f"fecontact{next(_counter)}_"
    system = _BorderedSystem(s, uh, ut, E, forms, prefix)
    load_norm = float(np.linalg.norm(s.load))
    k = s.k
    nloc = s.n_owned + (k if s.comm.rank == 0 else 0)
    X = PETSc.Vec().createMPI((nloc, PETSc.DECIDE), comm=s.comm)
    Fv = X.duplicate()
    t0, t_touch, pen = s.initial_translation()
    if problem.initial_translation_mm is not None:  # warm start
        t0 = np.asarray(problem.initial_translation_mm, dtype=float)
    q0 = (np.zeros(3) if problem.initial_rotation_rad is None
          else np.asarray(problem.initial_rotation_rad, dtype=float))
    system.ehat, system.t_touch = s.load / load_norm, t_touch
    X.set(0.0)
    if problem.initial_field is not None:
        init = np.asarray(problem.initial_field, dtype=float).reshape(-1)
        if init.shape != (s.n_owned,):
            _destroy(X, Fv, system)
            raise ValueError(f"initial_field has {init.size} values for {s.n_owned} owned dofs "
                             "(a field of another mesh or element?)")
        with X as xa:
            xa[: s.n_owned] = init
    if s.comm.rank == 0:
        with X as xa:
            xa[s.n_owned:] = np.concatenate([s.dirs @ t0, s.rot @ q0])
    Jshell = PETSc.Mat().createPython(((nloc, PETSc.DECIDE), (nloc, PETSc.DECIDE)),
                                      context=_ShellContext(system), comm=s.comm)
    Jshell.setUp()

    snes = PETSc.SNES().create(s.comm)
    snes.setOptionsPrefix(prefix)
    snes.setType("newtonls")
    snes.setFunction(system.residual, Fv)
    snes.setJacobian(system.jacobian, Jshell, Jshell)
    opt = problem.solver
    snes.setTolerances(rtol=opt.rtol, atol=opt.atol_rel_to_load * load_norm, stol=0.0,
                       max_it=opt.max_iterations)
    ksp = snes.getKSP()
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonContext(system)
    opts = PETSc.Options()
    user = {"snes_divergence_tolerance": "-1", "snes_linesearch_type": opt.linesearch}
    user.update(dict(opt.petsc_options))
    for key, val in user.items():
        opts[f"{prefix}{key}"] = val
    snes.setFromOptions()
    for key in user:
        del opts[f"{prefix}{key}"]
    if "snes_divergence_tolerance" not in dict(opt.petsc_options):
        snes.setDivergenceTolerance(-1.0)  # big first residuals are normal here

    history: list[float] = []
    snes.setMonitor(lambda _snes, _it, fnorm: history.append(float(fnorm)))
    if opt.monitor:
        def _print(_s: Any, it: int, fn: float) -> None:
            if s.comm.rank == 0:
                print(f"[fem_reference] Newton {it}: |F| = {fn:.3e}, translation "
                      f"{system.delta}", flush=True)

        snes.setMonitor(_print)
    if progress is not None:
        _monitor_progress(snes, system, s, pressure, progress)
    try:
        snes.solve(None, X)
    except Exception:
        err = system.error
        _destroy(snes, Jshell, X, Fv, system)
        if err is not None:
            raise err from None
        raise
    reason = snes.getConvergedReason()
    iters = snes.getIterationNumber()
    reason_name = _snes_reason_name(PETSc, reason)
    last = history[-1] if history else float("nan")
    if reason <= 0:
        _destroy(snes, Jshell, X, Fv, system)
        raise FEConvergenceError(
            f"Nitsche contact Newton did not converge ({element}, {s.n_global + k} dofs, "
            f"theta={problem.nitsche.theta}, gamma0={problem.nitsche.gamma0})",
            reason=reason_name, residual_norm=last, iterations=iters)
    system.set_state(X)
    iterative = system.iterative
    delta = np.array(system.delta)
    if system.limited_steps and opt.monitor and s.comm.rank == 0:
        print(f"[fem_reference] {system.limited_steps} Newton steps damped by the penetration "
              "limit")
    if system.singular_steps:
        warnings.append(f"{system.singular_steps} Newton iterate(s) lost contact; the last "
                        "regular contact stiffness was used for those steps")

    # ---- post-processing ----
    contact_force = np.array([s.scalar(fem.form(-pressure * nu[i] * s.ds_c)) for i in range(3)])
    force_residual, constraint_force = s.force_split(contact_force)
    if force_residual > opt.force_balance_rtol * load_norm:
        _destroy(snes, Jshell, X, Fv, system)
        raise FEConvergenceError(
            f"converged Newton solution does not balance the load: |integrated pressure force - "
            f"load| = {force_residual:.3e} N along the free directions "
            f"(> {opt.force_balance_rtol:g} * |load|)", reason="FORCE_BALANCE",
            residual_norm=last, iterations=iters)
    contact_moment = np.zeros(3)
    moment_residual = 0.0
    if len(s.rot):
        arm = ufl.SpatialCoordinate(s.mesh) - fem.Constant(s.mesh, s.ref_point)
        mom = ufl.cross(arm, -pressure * nu)
        contact_moment = np.array([s.scalar(fem.form(mom[i] * s.ds_c)) for i in range(3)])
        moment_residual = float(np.linalg.norm(s.rot @ (contact_moment - s.moment)))
        x = s.mesh.geometry.x
        size = max(s.comm.allreduce(float(x[:, i].max()) if len(x) else -np.inf, op=MPI.MAX)
                   - s.comm.allreduce(float(x[:, i].min()) if len(x) else np.inf, op=MPI.MIN)
                   for i in range(3))
        scale = max(float(np.linalg.norm(s.moment)), load_norm * size)
        if moment_residual > opt.force_balance_rtol * scale:
            _destroy(snes, Jshell, X, Fv, system)
            raise FEConvergenceError(
                f"converged Newton solution does not balance the moment: |moment of the contact "
                f"force about G - applied moment| = {moment_residual:.3e} N mm along the free "
                f"rotations", reason="MOMENT_BALANCE", residual_norm=last, iterations=iters)

    pdofs, _, Q = s.contact_points(1)
    phi = ufl.TestFunction(Q)
    mass = s.vector_owned(fem.form(phi * s.ds_c))
    load_vec = s.vector_owned(fem.form(pressure * phi * s.ds_c))
    nq = Q.dofmap.index_map.size_local
    own = np.sort(pdofs[pdofs < nq])
    pnod = np.where(mass[own] > 0, load_vec[own] / np.where(mass[own] > 0, mass[own], 1.0), 0.0)
    coords = Q.tabulate_dof_coordinates()[own]
    p_all = s.gather(pnod)
    x_all = s.gather(coords)
    peak = float(p_all.max()) if len(p_all) else 0.0
    ptol = fem.Constant(s.mesh, 1e-8 * max(peak, 1e-300))
    area = s.scalar(fem.form(ufl.conditional(ufl.gt(pressure, ptol), 1.0, 0.0) * s.ds_c))
    total_p = s.scalar(fem.form(pressure * s.ds_c))
    mean_p = total_p / area if area > 0 else 0.0
    strain = s.max_principal_strain(u)
    if strain > problem.strain_warning:
        warnings.append(f"max nominal strain {strain:.3f} exceeds {problem.strain_warning:.2f}: "
                        "small-strain elasticity is questionable")
    wall = time.perf_counter() - t_start
    fields = None
    if keep_fields:
        fields = {"mesh": s.mesh, "facet_tags": s.facet_tags, "solution": uh, "pressure": pressure,
                  "displacement": u, "space": s.V, "setup": s,
                  "ut_owned": system.ut.x.array[: s.n_owned].copy()}
    _destroy(snes, Jshell, X, Fv, system)
    return FEContactResult(
        bone_displacement_mm=s.dirs.T @ delta[:s.kt],
        free_directions=s.dirs.copy(),
        contact_points_mm=x_all,
        contact_pressure_mpa=p_all,
        peak_pressure_mpa=peak,
        mean_pressure_mpa=mean_p,
        contact_area_mm2=area,
        contact_area_definition=AREA_DEFINITION_NITSCHE,
        contact_force_n=contact_force,
        applied_force_n=s.load.copy(),
        force_residual_n=force_residual,
        constraint_force_n=constraint_force,
        n_dofs=int(s.n_global + k),
        linear_solver="iterative" if iterative else "direct",
        krylov_iterations=int(system.krylov_iterations),
        newton_iterations=int(iters),
        converged_reason=reason_name,
        wall_time_s=wall,
        max_nominal_strain=strain,
        element=element,
        method="nitsche",
        warnings=warnings,
        fields=fields,
        rotation_axes=s.rot.copy(),
        bone_rotation_rad=s.rot.T @ delta[s.kt:],
        contact_moment_nmm=contact_moment,
        moment_residual_nmm=moment_residual,
    )


def _monitor_progress(snes: Any, system: _BorderedSystem, s: _Setup, pressure: Any, progress: SolveProgress) -> None:
    """Newton and (iterative path) Krylov monitors writing ``progress`` lines (rank 0).

    The contact nodes are the P1 nodes of the contact surface whose lumped pressure is positive
    at the iterate; counting them is one facet assembly per Newton iteration, on every rank."""
    fem, ufl, MPI = s.m["fem"], s.m["ufl"], s.m["MPI"]
    pdofs, _, Q = s.contact_points(1)
    owned = np.sort(pdofs[pdofs < Q.dofmap.index_map.size_local])
    touching = fem.form(ufl.conditional(ufl.gt(pressure, 0.0), 1.0, 0.0) * ufl.TestFunction(Q) * s.ds_c)
    previous: list[np.ndarray] = []

    def newton(snes_: Any, it: int, fnorm: float) -> None:
        system.set_state(snes_.getSolution())  # the iterate (set_state only copies it into the fields)
        active = s.vector_owned(touching)[owned] > 0.0
        entered = left = 0
        if previous:
            entered = int(np.count_nonzero(active & ~previous[0]))
            left = int(np.count_nonzero(previous[0] & ~active))
        counts = s.comm.allreduce(np.array([np.count_nonzero(active), entered, left]), op=MPI.SUM)
        previous[:] = [active]
        if s.comm.rank == 0:
            progress.newton(int(it), float(fnorm), int(counts[0]), int(counts[1]), int(counts[2]))

    snes.setMonitor(newton)
    if system.iterative and s.comm.rank == 0:
        method = f"{system.ksp.getType()}+{'fieldsplit' if s.element == 'TH' else 'gamg'}"
        system.ksp.setMonitor(lambda _ksp, it, rnorm: progress.krylov(int(it), float(rnorm), method))


def _destroy(*objs: Any) -> None:
    for o in objs:
        if isinstance(o, _BorderedSystem):
            o.ksp.destroy()
            o.A.destroy()
            for obj in o.keep:
                obj.destroy()
            db = o.PETSc.Options()
            for key in o.option_keys:
                del db[key]
            o.wu.destroy()
            o.zu.destroy()
        elif o is not None:
            o.destroy()


# --------------------------------------------------------------------------------------------
# Variational inequality cross-check
# --------------------------------------------------------------------------------------------


def solve_contact_vi(problem: FEContactProblem, comm: Any = None, *, max_outer: int = 30,
                     keep_fields: bool = False) -> FEContactResult:
    """Cross-check: P1, plane obstacle whose normal is a coordinate axis, one free translation.

    Each inner solve is displacement-controlled (bonded face at t e) with bounds
    ``gap + u . nu >= 0`` on the contact-surface dofs, solved by PETSc ``vinewtonrsls``. The
    translation t is found by a safeguarded secant iteration on the bone reaction
    ``R(t) = e . (reaction of the bonded face)`` until ``R(t) = e . force_n`` (relative 1e-9).
    Contact pressure: nodal contact reaction divided by the lumped nodal area.
    ``problem.solver.petsc_options`` are added to the inner SNES options.
    """
    t_start = time.perf_counter()
    m = _fe_modules()
    fem, ufl, PETSc, MPI = m["fem"], m["ufl"], m["PETSc"], m["MPI"]
    comm = MPI.COMM_WORLD if comm is None else comm
    obs = problem.obstacle
    if not isinstance(obs, RigidPlane) or obs.axis() is None:
        raise ValueError("the VI path needs a RigidPlane whose normal is a coordinate axis")
    if problem.gap_history is not None or problem.gap_scale != 1.0:
        raise ValueError("the VI path solves elastic problems only (no Kelvin-Voigt shifted gap)")
    element = problem.resolved_element() if problem.element != "auto" else "P1"
    if element != "P1":
        raise ValueError("the VI path supports P1 elements only")
    s = _Setup(problem, comm, "P1")
    if s.k != 1:
        raise ValueError("the VI path supports exactly one free translation")
    e = s.dirs[0]
    c = obs.axis()
    nu_c = float(np.sign(obs.normal[c]))
    target = float(e @ s.load)

    uh = fem.Function(s.V, name="displacement")
    v = ufl.TestFunction(s.V)
    F = ufl.inner(s.sigma(uh), s.eps(v)) * s.dx
    tval = fem.Constant(s.mesh, np.zeros(3))
    bcs = [fem.dirichletbc(tval, s.bc_bonded_dofs, s.V)] + s.bcs[1:]
    prefix = f"fevi{next(_counter)}_"
    load_norm = float(np.linalg.norm(s.load))
    opts = {"snes_type": "vinewtonrsls", "snes_linesearch_type": "basic",
            "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps",
            "snes_rtol": 1e-12, "snes_atol": 1e-13 * load_norm, "snes_stol": 0.0,
            "snes_max_it": 50, "snes_divergence_tolerance": -1}
    opts.update(dict(problem.solver.petsc_options))  # the caller's extra SNES options, as for solve_contact
    nlp = m["fem_petsc"].NonlinearProblem(F, uh, bcs=bcs, petsc_options_prefix=prefix,
                                          petsc_options=opts)
    lb = nlp.x.duplicate()
    ub = nlp.x.duplicate()
    lb.set(PETSc.NINFINITY)
    ub.set(PETSc.INFINITY)
    nodes = fem.locate_dofs_topological(s.V, s.fdim, s.contact_facets)
    nloc_nodes = s.V.dofmap.index_map.size_local
    own_nodes = np.sort(nodes[nodes < nloc_nodes])
    pts = s.V.tabulate_dof_coordinates()[own_nodes]
    g, _ = obs.gap_and_normal(pts)
    idx = own_nodes * 3 + c
    with (lb if nu_c > 0 else ub) as bound:
        bound[idx] = -g if nu_c > 0 else g
    nlp.solver.setVariableBounds(lb, ub)

    a_vec = fem.form(F)
    b_idx, b_first = s.bcs[0].dof_indices()
    b_own = np.asarray(b_idx[:b_first])

    total_inner = 0

    def reaction(t: float) -> float:
        nonlocal total_inner
        tval.value[:] = t * e
        nlp.solve()
        reason = nlp.solver.getConvergedReason()
        total_inner += nlp.solver.getIterationNumber()
        if reason <= 0:
            raise FEConvergenceError(
                f"VI contact solve did not converge at translation {t:.6g} mm",
                reason=_snes_reason_name(PETSc, reason),
                residual_norm=nlp.solver.getFunctionNorm(), iterations=total_inner)
        b = s.vector_owned(a_vec)
        return s.comm.allreduce(float(np.dot(b[b_own], e[b_own % 3])), op=MPI.SUM)

    t0, t_touch, pen = s.initial_translation()
    ta, fa = t_touch, 0.0
    tb = float(e @ t0)
    fb = reaction(tb)
    outer = 1
    lo, hi = (ta, fa), None  # bracket: f(lo) < target <= f(hi)
    tol = 1e-9 * abs(target)
    while abs(fb - target) > tol:
        if outer >= max_outer:
            raise FEConvergenceError("VI secant on the translation did not converge",
                                     reason="DIVERGED_MAX_IT", residual_norm=abs(fb - target),
                                     iterations=total_inner)
        if fb < target:
            lo = (tb, fb)
        else:
            hi = (tb, fb)
        slope = (fb - fa) / (tb - ta) if tb != ta else 0.0
        tn = tb + (target - fb) / slope if slope > 0 else tb + 2.0 * (tb - ta)
        if hi is not None and not (lo[0] < tn < hi[0]):  # keep inside the bracket
            tn = lo[0] + (target - lo[1]) * (hi[0] - lo[0]) / (hi[1] - lo[1])
        ta, fa = tb, fb
        tb = tn
        fb = reaction(tb)
        outer += 1

    # nodal contact reactions -> pressure
    b = s.vector_owned(a_vec)
    lam_n = b[idx] * nu_c  # contact force on the body along nu (>= 0)
    mass = s.vector_owned(fem.form(v[c] * s.ds_c))[idx]  # lumped nodal areas, same layout
    pnod = np.where(mass > 0, lam_n / np.where(mass > 0, mass, 1.0), 0.0)
    pnod = np.where(pnod > 0, pnod, 0.0)
    fc_local = -nu_c * float(np.sum(lam_n))
    contact_force = np.zeros(3)
    contact_force[c] = s.comm.allreduce(fc_local, op=MPI.SUM)
    p_all = s.gather(pnod)
    x_all = s.gather(pts)
    peak = float(p_all.max()) if len(p_all) else 0.0
    active = pnod > 1e-8 * max(peak, 1e-300)
    area = s.comm.allreduce(float(np.sum(mass[active])), op=MPI.SUM)
    force_residual, constraint_force = s.force_split(contact_force)
    strain = s.max_principal_strain(uh)
    warnings: list[str] = []
    if strain > problem.strain_warning:
        warnings.append(f"max nominal strain {strain:.3f} exceeds {problem.strain_warning:.2f}")
    wall = time.perf_counter() - t_start
    fields = {"mesh": s.mesh, "solution": uh, "setup": s} if keep_fields else None
    return FEContactResult(
        bone_displacement_mm=tb * e,
        free_directions=s.dirs.copy(),
        contact_points_mm=x_all,
        contact_pressure_mpa=p_all,
        peak_pressure_mpa=peak,
        mean_pressure_mpa=abs(contact_force[c]) / area if area > 0 else 0.0,
        contact_area_mm2=area,
        contact_area_definition=AREA_DEFINITION_VI,
        contact_force_n=contact_force,
        applied_force_n=s.load.copy(),
        force_residual_n=force_residual,
        constraint_force_n=constraint_force,
        n_dofs=int(s.n_global),
        newton_iterations=int(total_inner),
        converged_reason="CONVERGED_SECANT",
        wall_time_s=wall,
        max_nominal_strain=strain,
        element="P1",
        method="vi",
        outer_iterations=outer,
        warnings=warnings,
        fields=fields,
    )
