"""Linear biphasic FE: cartilage that creeps by interstitial fluid flow (docs/method.md#the-biphasic-anchor).

Linear biphasic theory with incompressible constituents (Mow et al. 1980; the same equations as
Biot's consolidation with incompressible grains and fluid), small strain, unknowns the solid's
displacement u (mm) and the interstitial fluid pressure p (MPa):

    div(sigma_e(u) - p I) = 0,           sigma_e = lambda tr(eps) I + 2 mu eps   (drained matrix)
    div(du/dt) - div(k grad p) = 0,      k the permeability in mm^4/(N s)

(mixture volume balance: the solid's volume change is the fluid driven out, at the Darcy flux
-k grad p). Taylor-Hood P2-P1 (u, p), the inf-sup-stable pair, for the mixed form

    (sigma_e(u_n), eps(v)) - (p_n, div v) = (t_n, v)_loaded
    (div u_n, q) + dt* (k grad p_n, grad q) = (div h_n, q)

written symmetric (the second row negated) and solved by LU (MUMPS). Boundaries by facet tags:
fixed (u = 0, bonded to bone), rollers (one displacement component 0), drained (p = 0, free
draining) and one loaded face carrying a total traction or a prescribed displacement along one
axis; every other face is traction-free and impermeable (k grad p . n = 0).

Time (:func:`scheme_weights`): the flow equation is integrated implicitly, h_n and dt* from the
previous displacements:

* BDF2 (the default; second order, L-stable), variable step w = dt_n / dt_{n-1}:
  dt* = dt_n (1 + w) / (1 + 2w), h_n = ((1 + w)^2 u_{n-1} - w^2 u_{n-2}) / (1 + 2w); its first
  step after a start is backward Euler. Why not Crank-Nicolson: a step load puts the pressure
  p = sigma0 next to a drained face held at p = 0, a jump that excites the finest pressure modes
  most, and the trapezoid's amplification factor tends to -1 on them (they would alternate in
  sign from step to step, next to the platen, and decay slowly); BDF2's and backward Euler's
  tend to 0.
* backward Euler (first order): dt* = dt_n, h_n = u_{n-1}.

The instant of a load jump is undrained: integrating the flow equation across the jump,
div u cannot change (the flux is bounded), so for incompressible constituents the body answers
as an incompressible elastic solid of shear modulus mu (no volume change anywhere; in confined
compression no displacement at all, the fluid carrying the whole load). A step of zero length
(dt = 0: dt* = 0, h_n = u_{n-1}, the drained faces' p = 0 dropped, since no fluid has moved yet)
is that undrained response; histories start with it (:func:`solve_history`), and the smooth
evolution that follows begins from it. Between time points loads are read as linear, as EDEM
reads a load history.

Each step is a function of (the state at t_{n-1}, dt, the load at t_n) -> the state at t_n
(:meth:`BiphasicFE.step`, an immutable :class:`BiphasicState` that carries t_{n-2} for BDF2).
Contact (a rigid obstacle under force control) is :mod:`fem_reference.biphasic_contact`: the same
equations as bulk terms of :func:`fem_reference.contact.solve_contact`. The compiled forms take
dt*, the material and the load as dolfinx Constants, so one bilinear and one linear form (and one
small form per face whose means are read) serve every time step, material and mesh; the LU
factor of each distinct (dt*, boundary set) is kept (the last six).

Units: mm, N, MPa (N/mm^2), s; k in mm^4/(N s), so H_A k is in mm^2/s and the consolidation time
of a layer of thickness h is h^2 / (H_A k). Typical cartilage: H_A 0.5-1 MPa, k about 1e-15
m^4/(N s) = 1e-3 mm^4/(N s), the matrix's Poisson's ratio 0-0.1 (a 2 mm layer: T of 4000-8000 s).
Importing this module does not import dolfinx.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

from edem.mechanics import confined_modulus_mpa
from fem_reference.problem import TAG_ROLLER_X, TAG_ROLLER_Y, FEMesh, Roller
from geometries.errors import SolverError
from geometries.fe_solids import BONDED_TAG, CONTACT_TAG

#: time schemes of the flow equation (module docstring); the default is second order
TIME_SCHEMES = ("bdf2", "backward-euler")
DEFAULT_TIME_SCHEME = "bdf2"
#: LU factors kept per problem (undrained, first step, constant steps, and a displacement-controlled
#: twin of each need at most this many; graded steps factor each new one)
_KEPT_FACTORS = 6


@dataclass(frozen=True)
class BiphasicMaterial:
    """The drained solid matrix (Young's modulus and Poisson's ratio) and its permeability."""

    youngs_modulus_mpa: float
    poissons_ratio: float
    permeability_mm4_per_n_s: float

    def __post_init__(self) -> None:
        if not (self.youngs_modulus_mpa > 0.0 and math.isfinite(self.youngs_modulus_mpa)):
            raise ValueError(f"youngs_modulus_mpa must be > 0, got {self.youngs_modulus_mpa!r}")
        if not (-1.0 < self.poissons_ratio < 0.5):
            raise ValueError(f"the drained matrix's poissons_ratio must lie in (-1, 0.5), got {self.poissons_ratio!r}")
        if not (self.permeability_mm4_per_n_s > 0.0 and math.isfinite(self.permeability_mm4_per_n_s)):
            raise ValueError(f"permeability_mm4_per_n_s must be > 0, got {self.permeability_mm4_per_n_s!r}")

    @classmethod
    def from_aggregate_modulus(cls, aggregate_modulus_mpa: float, poissons_ratio: float,
                               permeability_mm4_per_n_s: float) -> "BiphasicMaterial":
        """From H_A = E (1 - nu) / ((1 + nu) (1 - 2 nu)), the confined (drained) modulus."""
        nu = poissons_ratio
        return cls(aggregate_modulus_mpa * (1.0 + nu) * (1.0 - 2.0 * nu) / (1.0 - nu), nu,
                   permeability_mm4_per_n_s)

    @property
    def aggregate_modulus_mpa(self) -> float:
        """H_A = lambda + 2 mu, the drained confined modulus."""
        return confined_modulus_mpa(self.youngs_modulus_mpa, self.poissons_ratio)

    @property
    def shear_modulus_mpa(self) -> float:
        return self.youngs_modulus_mpa / (2.0 * (1.0 + self.poissons_ratio))

    @property
    def lame_lambda_mpa(self) -> float:
        return self.aggregate_modulus_mpa - 2.0 * self.shear_modulus_mpa

    def consolidation_time_s(self, thickness_mm: float) -> float:
        """T = h^2 / (H_A k) of a layer of thickness h (s)."""
        return thickness_mm**2 / (self.aggregate_modulus_mpa * self.permeability_mm4_per_n_s)


def scheme_weights(scheme: str, dt_s: float, previous_dt_s: float | None) -> tuple[float, tuple[float, ...]]:
    """(dt*, (c_1, c_2)) of (div u_n, q) + dt* (k grad p_n, grad q) = (div (c_1 u_{n-1} + c_2 u_{n-2}), q).

    ``dt_s`` = 0 is the undrained jump (dt* = 0, h_n = u_{n-1}); ``previous_dt_s`` None or 0 (the
    first step after a start or a jump) makes BDF2 take a backward-Euler step. The weights are
    consistent (sum c_j = 1: a body at rest stays at rest).
    """
    if scheme not in TIME_SCHEMES:
        raise ValueError(f"unknown time scheme {scheme!r} (expected {' or '.join(TIME_SCHEMES)})")
    if not (dt_s >= 0.0 and math.isfinite(dt_s)):
        raise ValueError(f"the time step must be >= 0, got {dt_s!r} s")
    if dt_s == 0.0 or scheme == "backward-euler" or not previous_dt_s:
        return dt_s, (1.0,)
    w = dt_s / previous_dt_s
    return dt_s * (1.0 + w) / (1.0 + 2.0 * w), ((1.0 + w) ** 2 / (1.0 + 2.0 * w), -w * w / (1.0 + 2.0 * w))


@dataclass(frozen=True)
class Traction:
    """A total traction (MPa, (3,)) on the loaded face: fluid and solid together carry it."""

    traction_mpa: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        t = np.asarray(self.traction_mpa, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f"Traction.traction_mpa must be 3 finite numbers, got {self.traction_mpa!r}")


@dataclass(frozen=True)
class PrescribedDisplacement:
    """The loaded face's displacement along coordinate ``axis`` (mm); the other components free
    (a frictionless platen)."""

    axis: int
    displacement_mm: float

    def __post_init__(self) -> None:
        if self.axis not in (0, 1, 2) or not math.isfinite(self.displacement_mm):
            raise ValueError(f"PrescribedDisplacement needs an axis 0, 1 or 2 and a finite displacement, got {self!r}")


Load = Traction | PrescribedDisplacement


@dataclass(frozen=True)
class BiphasicBoundaries:
    """Facet tags of the boundary conditions (module docstring); untagged faces are
    traction-free and impermeable."""

    fixed_tags: tuple[int, ...] = (BONDED_TAG,)
    rollers: tuple[Roller, ...] = ()
    drained_tags: tuple[int, ...] = (CONTACT_TAG,)
    loaded_tag: int = CONTACT_TAG


#: a slab of :func:`fem_reference.meshes.box_slab` in a confining chamber: fixed impermeable
#: bottom, lateral faces on rollers, loaded through a free-draining platen on top
CONFINED_COMPRESSION = BiphasicBoundaries(rollers=(Roller(TAG_ROLLER_X, 0), Roller(TAG_ROLLER_Y, 1)))


@dataclass(frozen=True)
class BiphasicState:
    """The mixed (u, p) solution at ``time_s`` (the dolfinx Function's local array, ghosts
    included) under ``load``; ``previous`` is the state before it (for BDF2; its own previous
    dropped), None after a start or an undrained jump."""

    time_s: float
    solution: np.ndarray = field(repr=False)
    load: Load
    previous: "BiphasicState | None" = field(default=None, repr=False)


class BiphasicFE:
    """The compiled biphasic problem on one mesh (module docstring): spaces, forms, boundary
    conditions and the kept LU factors. Its states are :class:`BiphasicState`."""

    def __init__(self, mesh: FEMesh, material: BiphasicMaterial, boundaries: BiphasicBoundaries) -> None:
        from fem_reference.fe_stack import fe_modules

        m = self._m = fe_modules()
        fem, ufl, bu = m["fem"], m["ufl"], m["basix_ufl"]
        self.material, self.boundaries = material, boundaries
        msh = self._mesh = mesh.mesh
        self._tags = mesh.facet_tags
        self._fdim = msh.topology.dim - 1
        msh.topology.create_connectivity(self._fdim, msh.topology.dim)
        cell = msh.basix_cell()
        self.W = fem.functionspace(msh, bu.mixed_element([bu.element("Lagrange", cell, 2, shape=(3,)),
                                                          bu.element("Lagrange", cell, 1)]))
        self._solution = fem.Function(self.W)
        self._history = fem.Function(self.W)  # h_n (its pressure part unused)
        c = {name: fem.Constant(msh, value) for name, value in (
            ("mu", material.shear_modulus_mpa), ("lam", material.lame_lambda_mpa),
            ("k", material.permeability_mm4_per_n_s), ("flow_dt", 0.0), ("platen", 0.0))}
        c["traction"] = fem.Constant(msh, np.zeros(3))
        self._c = c
        u, p = ufl.TrialFunctions(self.W)
        v, q = ufl.TestFunctions(self.W)
        h_u, _ = ufl.split(self._history)

        def eps(w: Any) -> Any:
            return ufl.sym(ufl.grad(w))

        def sigma_e(w: Any) -> Any:
            return 2.0 * c["mu"] * eps(w) + c["lam"] * ufl.tr(eps(w)) * ufl.Identity(3)

        self._ds = ufl.Measure("ds", domain=msh, subdomain_data=self._tags)
        a = (ufl.inner(sigma_e(u), eps(v)) - p * ufl.div(v) - q * ufl.div(u)
             - c["flow_dt"] * c["k"] * ufl.inner(ufl.grad(p), ufl.grad(q))) * ufl.dx
        L = ufl.inner(c["traction"], v) * self._ds(boundaries.loaded_tag) - q * ufl.div(h_u) * ufl.dx
        self._a, self._L = fem.form(a), fem.form(L)
        self._face_forms: dict[int, Any] = {}
        self._dof_cache: dict[tuple, np.ndarray] = {}
        for tag in (*boundaries.fixed_tags, *(r.tag for r in boundaries.rollers), *boundaries.drained_tags,
                    boundaries.loaded_tag):
            self._facets(tag)  # refuse a boundary condition on a tag the mesh lacks, now
        self._solvers: dict[tuple, tuple[Any, list]] = {}
        self._unconstrained: Any = None
        self._b = m["fem_petsc"].create_vector(self.W)
        index_map = self.W.dofmap.index_map
        self._n_owned = index_map.size_local * self.W.dofmap.index_map_bs
        self._pressure_dofs = np.asarray(self.W.sub(1).collapse()[1])
        self._pressure_dofs = self._pressure_dofs[self._pressure_dofs < self._n_owned]

    # ---------------------------------------------------------------------------------------
    # boundary conditions and the kept factors
    # ---------------------------------------------------------------------------------------

    def _facets(self, tag: int) -> np.ndarray:
        facets = self._tags.find(tag)
        if self._mesh.comm.allreduce(len(facets)) == 0:
            raise ValueError(f"the biphasic mesh has no facets tagged {tag}")
        return facets

    def _dofs(self, tag: int, axis: int | None) -> np.ndarray:
        """The mixed space's dofs of displacement component ``axis`` (None: the pressure) on ``tag``."""
        if (tag, axis) not in self._dof_cache:
            space = self.W.sub(1) if axis is None else self.W.sub(0).sub(axis)
            self._dof_cache[tag, axis] = self._m["fem"].locate_dofs_topological(space, self._fdim, self._facets(tag))
        return self._dof_cache[tag, axis]

    def _bcs(self, drained: bool, platen_axis: int | None) -> list:
        fem = self._m["fem"]
        b = self.boundaries
        zero = [(tag, axis) for tag in b.fixed_tags for axis in range(3)]
        zero += [(r.tag, int(r.axis)) for r in b.rollers]
        zero += [(tag, None) for tag in b.drained_tags] if drained else []
        space = {None: self.W.sub(1)} | {i: self.W.sub(0).sub(i) for i in range(3)}
        bcs = [fem.dirichletbc(0.0, self._dofs(tag, axis), space[axis]) for tag, axis in zero]
        if platen_axis is not None:
            bcs.append(fem.dirichletbc(self._c["platen"], self._dofs(b.loaded_tag, platen_axis), space[platen_axis]))
        return bcs

    def _solver(self, flow_dt: float, platen_axis: int | None) -> tuple[float, Any, list]:
        """(dt*, the LU-factored matrix, its boundary conditions) of (dt*, boundary set), kept.

        A kept dt* within 1e-9 of the one asked for is reused (steps equal up to rounding, as
        from numpy.linspace, share one factor; the scheme stays consistent, its weights sum to 1
        whatever dt*, and the difference is a 1e-9 relative change of one step's length)."""
        key = next((k for k in self._solvers if k[1] == platen_axis and abs(k[0] - flow_dt) <= 1e-9 * flow_dt),
                   (flow_dt, platen_axis))
        if key not in self._solvers:
            PETSc = self._m["PETSc"]
            bcs = self._bcs(drained=flow_dt > 0.0, platen_axis=platen_axis)
            self._c["flow_dt"].value = flow_dt
            A = self._m["fem_petsc"].assemble_matrix(self._a, bcs=bcs)
            A.assemble()
            ksp = PETSc.KSP().create(self._mesh.comm)
            ksp.setOperators(A)
            ksp.setType("preonly")
            ksp.getPC().setType("lu")
            ksp.getPC().setFactorSolverType("mumps")
            self._solvers[key] = (ksp, bcs)
            if len(self._solvers) > _KEPT_FACTORS:  # graded steps: drop the oldest factor
                old = self._solvers.pop(next(iter(self._solvers)))[0]
                old.getOperators()[0].destroy()
                old.destroy()
        return (key[0], *self._solvers[key])

    def _set_load(self, load: Load) -> int | None:
        if isinstance(load, Traction):
            self._c["traction"].value[:] = np.asarray(load.traction_mpa, dtype=float)
            return None
        if isinstance(load, PrescribedDisplacement):
            self._c["traction"].value[:] = 0.0
            self._c["platen"].value = float(load.displacement_mm)
            return int(load.axis)
        raise TypeError(f"a biphasic load is a Traction or a PrescribedDisplacement, got {load!r}")

    # ---------------------------------------------------------------------------------------
    # time stepping
    # ---------------------------------------------------------------------------------------

    def at_rest(self, time_s: float) -> BiphasicState:
        """The undeformed body with no pressure and no load."""
        return BiphasicState(float(time_s), np.zeros_like(self._solution.x.array), Traction())

    def step(self, state: BiphasicState, dt_s: float, load: Load,
             scheme: str = DEFAULT_TIME_SCHEME) -> BiphasicState:
        """The state at t_n = ``state.time_s + dt_s`` under ``load`` (module docstring); ``dt_s``
        = 0 is the undrained response to a jump of the load at t_{n-1}."""
        previous = state.previous
        previous_dt = None if previous is None else state.time_s - previous.time_s
        flow_dt, weights = scheme_weights(scheme, float(dt_s), previous_dt)
        platen_axis = self._set_load(load)
        flow_dt, ksp, bcs = self._solver(flow_dt, platen_axis)
        self._c["flow_dt"].value = flow_dt
        h = self._history.x.array
        h[:] = weights[0] * state.solution
        if len(weights) > 1:
            h += weights[1] * previous.solution
        fp, PETSc = self._m["fem_petsc"], self._m["PETSc"]
        b = self._b
        with b.localForm() as local:
            local.set(0.0)
        fp.assemble_vector(b, self._L)
        fp.apply_lifting(b, [self._a], bcs=[bcs])
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fp.set_bc(b, bcs)
        x = self._solution
        ksp.solve(b, x.x.petsc_vec)
        x.x.scatter_forward()
        # a singular system still factors, into a finite but meaningless solution: its residual
        # tells (1e-8: far above the LU's round-off, at most 2.5e-15 measured on the columns)
        residual = b.duplicate()
        ksp.getOperators()[0].mult(x.x.petsc_vec, residual)
        residual.axpy(-1.0, b)
        relative = residual.norm() / max(b.norm(), 1e-300)
        residual.destroy()
        if not relative <= 1e-8:
            raise SolverError(
                f"the biphasic system of the step to t = {state.time_s + dt_s:g} s is singular (relative "
                f"residual {relative:.1e}): an undrained jump of a prescribed displacement on a body whose "
                "whole boundary has its normal displacement prescribed (the fluid cannot leave: ramp the "
                "displacement instead), or boundary conditions that leave a rigid motion free")
        kept = None if dt_s == 0.0 else replace(state, previous=None)
        return BiphasicState(state.time_s + float(dt_s), x.x.array.copy(), load, kept)

    # ---------------------------------------------------------------------------------------
    # what a state gives
    # ---------------------------------------------------------------------------------------

    def _face_integrals(self, state: BiphasicState, tag: int) -> tuple[np.ndarray, float, float]:
        """(integral of u (3,), of p, area) over the facets tagged ``tag``: one compiled form per
        tag, (w . u + c p + a) ds, its Constants picking the integrand."""
        fem, ufl = self._m["fem"], self._m["ufl"]
        if tag not in self._face_forms:
            self._facets(tag)
            w, cp, ca = fem.Constant(self._mesh, np.zeros(3)), fem.Constant(self._mesh, 0.0), fem.Constant(self._mesh, 0.0)
            u, p = ufl.split(self._solution)
            form = fem.form((ufl.inner(w, u) + cp * p + ca) * self._ds(tag))
            self._face_forms[tag] = (form, w, cp, ca)
        form, w, cp, ca = self._face_forms[tag]
        self._solution.x.array[:] = state.solution

        def integral(wv: np.ndarray, pv: float, av: float) -> float:
            w.value[:], cp.value, ca.value = wv, pv, av
            return self._mesh.comm.allreduce(fem.assemble_scalar(form))

        eye = np.eye(3)
        return (np.array([integral(eye[i], 0.0, 0.0) for i in range(3)]),
                integral(np.zeros(3), 1.0, 0.0), integral(np.zeros(3), 0.0, 1.0))

    def face_mean_displacement_mm(self, state: BiphasicState, tag: int) -> np.ndarray:
        """The displacement averaged over the facets tagged ``tag`` (3,)."""
        u, _, area = self._face_integrals(state, tag)
        return u / area

    def face_mean_pressure_mpa(self, state: BiphasicState, tag: int) -> float:
        """The fluid pressure averaged over the facets tagged ``tag``."""
        _, p, area = self._face_integrals(state, tag)
        return p / area

    def _unconstrained_product(self, state: BiphasicState) -> np.ndarray:
        """A x with A the matrix at dt* = 0 without boundary conditions (owned entries): its
        displacement rows are the internal forces, its pressure rows -(div u, q)."""
        if self._unconstrained is None:
            self._c["flow_dt"].value = 0.0
            self._unconstrained = self._m["fem_petsc"].assemble_matrix(self._a)
            self._unconstrained.assemble()
        x = self._unconstrained.createVecRight()
        x.array[:] = state.solution[: self._n_owned]
        y = self._unconstrained.createVecLeft()
        self._unconstrained.mult(x, y)
        return y.array.copy()

    def reaction_force_n(self, state: BiphasicState, tag: int) -> np.ndarray:
        """The force (N, (3,)) that the supports of the facets tagged ``tag`` (fixed, rollers or
        prescribed displacement) exert on the body: the residual of the displacement equations at
        their dofs, the variationally consistent reaction (total stress: solid and fluid)."""
        fp = self._m["fem_petsc"]
        internal = self._unconstrained_product(state)
        self._set_load(state.load)
        b = self._b
        with b.localForm() as local:
            local.set(0.0)
        self._history.x.array[:] = 0.0
        fp.assemble_vector(b, self._L)
        b.ghostUpdate(addv=self._m["PETSc"].InsertMode.ADD, mode=self._m["PETSc"].ScatterMode.REVERSE)
        residual = internal - b.array[: self._n_owned]
        force = np.zeros(3)
        for axis in range(3):
            dofs = self._dofs(tag, axis)
            force[axis] = residual[dofs[dofs < self._n_owned]].sum()
        return np.array(self._mesh.comm.allreduce(force))

    def volume_change_mm3(self, state: BiphasicState) -> float:
        """The integral of div u over the body: the fluid volume driven out (0 at an undrained
        instant, exactly in Taylor-Hood, whose pressure space holds the constants)."""
        product = self._unconstrained_product(state)
        return -self._mesh.comm.allreduce(float(product[self._pressure_dofs].sum()))


def solve_history(fe: BiphasicFE, times_s: Sequence[float], loads: Sequence[Load],
                  scheme: str = DEFAULT_TIME_SCHEME) -> list[BiphasicState]:
    """The states at ``times_s`` (increasing) under ``loads`` (one per time point, linear between
    them), the body at rest before the first: its state is the undrained response to the first
    load (module docstring)."""
    times = np.asarray(times_s, dtype=float)
    if len(times) != len(loads) or len(times) == 0:
        raise ValueError(f"one load per time point: {len(loads)} loads for {len(times)} times")
    if np.any(np.diff(times) <= 0.0):
        raise ValueError("the biphasic time points must increase strictly")
    states = [fe.step(fe.at_rest(times[0]), 0.0, loads[0], scheme)]
    for t, load in zip(times[1:], loads[1:]):
        states.append(fe.step(states[-1], float(t) - states[-1].time_s, load, scheme))
    return states
