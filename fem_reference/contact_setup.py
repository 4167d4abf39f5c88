"""The shared set-up of one FE contact problem: what the Nitsche solver (:mod:`fem_reference.contact`)
and the variational-inequality cross-check (:mod:`fem_reference.contact_vi`) both build.

:class:`ContactSetup`: the mesh (:func:`materialize_mesh`), the displacement space (P1, P2, or
Taylor-Hood P2-P1 u-p), the bonded and roller conditions on u~, the material, the measures, the
rigid modes of the bone's free translations and rotations, the obstacle's gap and normal (shifted
for a Kelvin-Voigt step), the starting translation, the parallel reductions, and
:meth:`ContactSetup.result`, the one place an :class:`FEContactResult` is assembled.

Heavy imports (dolfinx, ufl, basix, PETSc) happen inside the functions (:mod:`fem_reference.fe_stack`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .fe_stack import fe_modules
from .problem import (
    FEContactProblem,
    FEContactResult,
    FEConvergenceError,
    FEMesh,
    RigidCylinder,
    RigidPlane,
    RigidSurface,
)


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



class ContactSetup:
    """Spaces, boundary conditions and UFL pieces shared by the Nitsche and VI paths."""

    def __init__(self, problem: FEContactProblem, comm: Any, element: str) -> None:
        m = self.m = fe_modules()
        fem, ufl = m["fem"], m["ufl"]
        self.problem = problem
        data = materialize_mesh(problem, comm)
        self.mesh = mesh = data.mesh
        self.comm = mesh.comm
        self.facet_tags = data.facet_tags
        self.cell_tags = data.cell_tags
        if self.facet_tags is None:
            raise ValueError("the FE mesh needs facet tags (bonded and contact faces)")
        self.tdim = mesh.topology.dim
        if self.tdim != 3 or mesh.geometry.dim != 3:
            raise ValueError("fem_reference solves 3D problems (use a thin slice for plane strain)")
        self.fdim = self.tdim - 1
        mesh.topology.create_connectivity(self.fdim, self.tdim)
        self.element = element
        self.degree = 1 if element == "P1" else 2
        self.bonded_facets = self._bonded_facets()
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

        self.lam, self.mu = self._material()
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

    def _bonded_facets(self) -> np.ndarray:
        """The facets held by the bone (u~ = 0 there)."""
        return self._facets(self.problem.bonded_tag, "bonded")

    def _material(self) -> tuple[Any, Any]:
        """Lame's (lambda, mu) in MPa as UFL coefficients."""
        fem = self.m["fem"]
        lam, mu = self.problem.lame()
        return fem.Constant(self.mesh, float(lam)), fem.Constant(self.mesh, float(mu))

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

    def relative_displacement(self, u: Any) -> Any:
        """The displacement the contact condition measures: ``u`` against a rigid obstacle (a
        deformable one subtracts its own, :class:`fem_reference.two_body.TwoBodySetup`)."""
        return u

    def moved_pairing(self, uh: Any) -> Any:
        """A rigid obstacle's pairing never moves: None (see :meth:`fem_reference.two_body.TwoBodySetup.moved_pairing`)."""
        return None

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
        return (shifted if p.gap_history is None else shifted + ufl.dot(self.gap_history(), nu)), nu

    def gap_history(self) -> Any:
        """The history h_n that shifts the gap (:class:`FEContactProblem` ``gap_history``): against
        a rigid obstacle the body's own (a deformable one subtracts its own history at the paired
        points, :meth:`fem_reference.two_body.TwoBodySetup.gap_history`)."""
        return self.problem.gap_history

    def shifted_gap(self, dofs: np.ndarray, gap: np.ndarray, normal: np.ndarray,
                    degree: int | None = None) -> np.ndarray:
        """The gap of :meth:`obstacle_ufl` at the contact-surface dofs ``dofs`` of
        :meth:`contact_points` (``degree``; default the displacement's)."""
        p = self.problem
        if p.gap_history is None:
            return float(p.gap_scale) * gap
        h = self.gap_history()
        if degree is not None and degree != self.degree:
            h = self.m["fem"].Function(self.m["fem"].functionspace(self.mesh, ("Lagrange", degree, (3,))))
            h.interpolate(self.gap_history())
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
        (:meth:`fem_reference.contact.BorderedSystem.step_limit`).
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
        """(|the free part of contact force - load|, its part along the fixed translations)."""
        diff = contact_force - self.load
        free = self.dirs.T @ (self.dirs @ diff)
        return float(np.linalg.norm(free)), diff - free

    def result(self, *, method: str, area_definition: str, translation_mm: np.ndarray,
               points_mm: np.ndarray, pressure_mpa: np.ndarray, peak_pressure_mpa: float,
               mean_pressure_mpa: float, contact_area_mm2: float, contact_force_n: np.ndarray,
               displacement: Any, n_dofs: int, newton_iterations: int, converged_reason: str,
               started: float, warnings: list[str], fields: dict | None, **details: Any,
               ) -> FEContactResult:
        """The :class:`FEContactResult` of a converged solve of this set-up's problem.

        The solver gives what it measured: the bone's translation (3,) in mm, the gathered
        contact-surface points (n, 3) and nodal pressures (n,) in MPa with their peak, the mean
        pressure, the contact area (mm^2, by ``area_definition``), the force on the obstacle (3,)
        in N, the displacement (a UFL vector, for the strain), the counts and its start
        (``time.perf_counter()``). This fills what every solver derives alike: the free
        directions, the applied load and its balance split (:meth:`force_split`), the largest
        principal strain (a warning above ``problem.strain_warning``) and the wall time.
        ``details``: the solver's own fields of :class:`FEContactResult` (linear solver,
        rotations, outer iterations...).
        """
        force_residual, constraint_force = self.force_split(contact_force_n)
        strain = self.max_principal_strain(displacement)
        if strain > self.problem.strain_warning:
            warnings.append(f"max nominal strain {strain:.3f} exceeds {self.problem.strain_warning:.2f}: "
                            "small-strain elasticity is questionable")
        return FEContactResult(
            bone_displacement_mm=translation_mm,
            free_directions=self.dirs.copy(),
            contact_points_mm=points_mm,
            contact_pressure_mpa=pressure_mpa,
            peak_pressure_mpa=peak_pressure_mpa,
            mean_pressure_mpa=mean_pressure_mpa,
            contact_area_mm2=contact_area_mm2,
            contact_area_definition=area_definition,
            contact_force_n=contact_force_n,
            applied_force_n=self.load.copy(),
            force_residual_n=force_residual,
            constraint_force_n=constraint_force,
            n_dofs=int(n_dofs),
            newton_iterations=int(newton_iterations),
            converged_reason=converged_reason,
            wall_time_s=time.perf_counter() - started,
            max_nominal_strain=strain,
            element=self.element,
            method=method,
            warnings=warnings,
            fields=fields,
            **details,
        )

