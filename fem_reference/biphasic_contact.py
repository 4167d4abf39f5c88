"""A biphasic layer in frictionless contact with a rigid obstacle under force control (docs/method.md#biphasic-contact).

The material is :mod:`fem_reference.biphasic`'s (linear biphasic, incompressible constituents,
Taylor-Hood P2-P1 in (u, p)); the contact, the force control and the Newton loop are
:func:`fem_reference.contact.solve_contact`'s, unchanged: this module gives it the bulk terms of
a time step through :attr:`fem_reference.problem.FEContactProblem.bulk_form`. With the drained
matrix's Lame constants lambda, mu (the problem's Young's modulus and Poisson's ratio), the
permeability k and the time step's dt* and history h_n (:func:`fem_reference.biphasic.scheme_weights`),
the bulk residual of a step is the Taylor-Hood contact problem's with the compressibility term
replaced by the flow term:

    (sigma_e(u), eps(v)) - (p, div v) - (q, div(u - h_n)) - dt* (k grad p, grad q)
    + dt* sum over drained faces of chi k [(grad p . n) q + (grad q . n) p - (beta / h) p q]

(the flow row negated, so that the step's matrix is symmetric but for the contact terms). The
total stress sigma_e(u) - p I is what Nitsche's contact terms take, so the contact pressure is the
total traction (fluid and solid together). h_n enters through its divergence only, so the bone's
rigid motion in it does no harm.

Fluid boundary conditions. The bonded face (on the bone) and symmetry planes are impermeable (the
natural condition). The free faces (``drained_tags``, the layer's cut edges) drain freely: p = 0.
On the contact face the counter-surface decides (:data:`COUNTER_SURFACES`):

* ``impermeable`` (the default; the joint: cartilage against cartilage or a sealed indenter): the
  fluid cannot cross the contact, so p = 0 only where the face is not in contact (chi = 1 where
  the Nitsche contact pressure is 0) and no flux where it is (chi = 0). chi switches with the
  contact set: it is the indicator of the iterate's contact set, as in the contact's semismooth
  Newton (its derivative, a Dirac at the switch, is dropped, as that of the contact's max);
* ``porous`` (a free-draining platen): p = 0 on the whole contact face (chi = 1), in contact or not.
  Confined compression through contact is then Mow's creep test, which checks this module against
  its closed form. An impermeable punch on a confined column would not creep at all.

p = 0 is imposed weakly, by Nitsche's symmetric method with beta = :data:`DRAINAGE_BETA` and h the
cell height over the facet (3 volume / facet area, as the contact's), so that it can switch with
the contact set at each quadrature point.

Where a quadrature point's own drainage moves it across the contact boundary (drained, it comes into
contact; sealed, it leaves it), the sharp switch has no discrete solution and Newton cycles between
the two states. The step is then solved again with the drainage set frozen over each solve: first
the previous time point's contact set, then each solve's own, until the set no longer changes
(:data:`MAX_DRAINAGE_PASSES` at most; where it still changes, the area that disagrees is warned).

Time. BDF2 (default) or backward Euler, as :mod:`fem_reference.biphasic`. A history starts at rest
(:meth:`BiphasicContactHistory.start_at_rest`; loads are linear between time points, so the first
loaded step is a fast ramp) or, with a load at its first time point, with the undrained response to
it (dt* = 0, h = 0: an incompressible elastic body of shear modulus mu, the instant of a load
jump).

Units: mm, N, MPa, s; k in mm^4/(N s). Importing this module does not import dolfinx.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fem_reference.biphasic import DEFAULT_TIME_SCHEME, TIME_SCHEMES, scheme_weights
from fem_reference.problem import FEContactProblem, FEContactResult, FEConvergenceError
from geometries.fe_solids import FREE_TAG

#: the fluid boundary condition on the contact face (module docstring)
COUNTER_SURFACES = {
    "impermeable": "the fluid cannot cross the contact: p = 0 where the contact face is not in contact, no flux where it is",
    "porous": "a free-draining counter-surface: p = 0 on the whole contact face",
}
DEFAULT_COUNTER_SURFACE = "impermeable"
#: Nitsche's beta of p = 0: coercive above 2 x 3 (the trace inverse constant of P1 on a tetrahedron
#: over its height); on confined creep through a porous punch (8 cells, BDF2, T/100) the first
#: step's error is 2.1 % of the equilibrium displacement at beta 3, 0.99 % at 10, 0.76 % at 100 and
#: 0.74 % at 1000, against 0.73 % with p = 0 imposed strongly (fem_reference.biphasic)
DRAINAGE_BETA = 100.0
#: BDF2's zero-stability bound on the ratio of consecutive steps (1 + sqrt 2): above it an
#: indentation overshot its drained displacement by 8 % (step ratio 3.16; 0.23 % at 1.33)
BDF2_MAX_STEP_RATIO = 1.0 + 2.0 ** 0.5
#: solves of a step with the drainage set frozen, after Newton has cycled between drainage sets
MAX_DRAINAGE_PASSES = 6


class _BulkTerms:
    """The bulk terms of one step (module docstring), as :attr:`FEContactProblem.bulk_form` gives
    them to :func:`fem_reference.contact.solve_contact`."""

    def __init__(self, history: "BiphasicContactHistory", s: Any, uh: Any, w: Any) -> None:
        ufl = history.fe["ufl"]
        self.history, self.setup, self.solution = history, s, uh
        u, p = ufl.split(uh)
        v, q = ufl.split(w)
        self.displacement, self.test_displacement = u, v
        self._p, self._q = p, q
        self.stress_u = s.sigma(u) - p * ufl.Identity(3)
        self.stress_v = s.sigma(v) - q * ufl.Identity(3)
        self.changed_area: Any = None  # the frozen drainage set's check (BiphasicContactHistory.solve)

    def _in_contact(self, contact_pressure: Any, state: Any = None) -> Any:
        ufl = self.history.fe["ufl"]
        pressure = contact_pressure if state is None else ufl.replace(contact_pressure, {self.solution: state})
        return ufl.conditional(ufl.gt(pressure, 0.0), 1.0, 0.0)

    def residual(self, contact_pressure: Any) -> Any:
        h = self.history
        fem, ufl = h.fe["fem"], h.fe["ufl"]
        s, u, v, p, q = self.setup, self.displacement, self.test_displacement, self._p, self._q
        c = h.constants
        history_u, _ = ufl.split(h.history_field)
        flow = c["flow_dt"] * c["k"]
        form = (ufl.inner(s.sigma(u), s.eps(v)) - p * ufl.div(v) - q * ufl.div(u - history_u)
                - flow * ufl.inner(ufl.grad(p), ufl.grad(q))) * s.dx
        n = ufl.FacetNormal(s.mesh)
        height = 3.0 * ufl.CellVolume(s.mesh) / ufl.FacetArea(s.mesh)
        drain = flow * (ufl.dot(ufl.grad(p), n) * q + ufl.dot(ufl.grad(q), n) * p - c["beta"] / height * p * q)
        if h.counter_surface == "porous":
            form += drain * s.ds_c
        elif h.frozen_drainage is None:
            form += (1.0 - self._in_contact(contact_pressure)) * drain * s.ds_c
        else:
            frozen = self._in_contact(contact_pressure, h.frozen_drainage)
            form += (1.0 - frozen) * drain * s.ds_c
            self.changed_area = fem.form(abs(frozen - self._in_contact(contact_pressure, h.candidate)) * s.ds_c)
        for tag in h.drained_tags:
            form += drain * s.ds(tag)
        self.fluid_share = fem.form(self._in_contact(contact_pressure) * p * s.ds_c)
        self.total_pressure = fem.form(contact_pressure * s.ds_c)
        return form


@dataclass
class _State:
    time_s: float
    solution: np.ndarray  # the mixed (u, p) Function's local array, u with the bone's rigid motion
    translation_mm: np.ndarray  # (3,) the bone's
    rotation_rad: np.ndarray  # (3,)
    ut_owned: np.ndarray  # the solve's elastic part (owned values): the next step's warm start


class BiphasicContactHistory:
    """The states of a biphasic contact run on one mesh (module docstring).

    ``mesh``: the :class:`fem_reference.problem.FEMesh` every time point is solved on;
    ``permeability_mm4_per_n_s``: k; the drained matrix is each problem's Young's modulus and
    Poisson's ratio. ``scheme``: :data:`fem_reference.biphasic.TIME_SCHEMES`; ``counter_surface``:
    :data:`COUNTER_SURFACES`; ``drained_tags``: the faces held at p = 0 (the free faces).
    """

    def __init__(self, mesh: Any, permeability_mm4_per_n_s: float, scheme: str = DEFAULT_TIME_SCHEME,
                 counter_surface: str = DEFAULT_COUNTER_SURFACE, drained_tags: tuple[int, ...] = (FREE_TAG,)) -> None:
        from fem_reference.fe_stack import fe_modules

        if scheme not in TIME_SCHEMES:
            raise ValueError(f"unknown biphasic time scheme {scheme!r} (expected {' or '.join(TIME_SCHEMES)})")
        if counter_surface not in COUNTER_SURFACES:
            raise ValueError(f"unknown counter-surface {counter_surface!r} (expected {' or '.join(COUNTER_SURFACES)})")
        if not (permeability_mm4_per_n_s > 0.0 and np.isfinite(permeability_mm4_per_n_s)):
            raise ValueError(f"the permeability must be > 0, got {permeability_mm4_per_n_s!r}")
        fe = self.fe = fe_modules()
        fem, bu = fe["fem"], fe["basix_ufl"]
        self.mesh = mesh
        self.permeability_mm4_per_n_s = float(permeability_mm4_per_n_s)
        self.scheme, self.counter_surface = scheme, counter_surface
        self.drained_tags = tuple(int(t) for t in drained_tags)
        msh = mesh.mesh
        cell = msh.basix_cell()
        # the contact solver's Taylor-Hood space (fem_reference.contact_setup): the same element on
        # the same mesh, so the same dof layout
        space = fem.functionspace(msh, bu.mixed_element([bu.element("Lagrange", cell, 2, shape=(3,)),
                                                          bu.element("Lagrange", cell, 1)]))
        self.history_field = fem.Function(space)  # h_n (its pressure part unused)
        self.candidate = fem.Function(space)  # a solve's solution, whose drainage set is checked
        self._space = space
        self.frozen_drainage: Any = None  # a Function whose contact set is the drainage set (None: the iterate's)
        self.constants = {name: fem.Constant(msh, float(value)) for name, value in (
            ("flow_dt", 0.0), ("k", self.permeability_mm4_per_n_s), ("beta", DRAINAGE_BETA))}
        self.states: list[_State] = []
        self.step_warnings: list[str] = []  # of the prepared step
        self._terms: _BulkTerms | None = None
        self.fluid_load_fraction: list[float] = []  # per solved time point
        self.drainage_passes: list[int] = []  # solves per time point (1 unless Newton cycled)

    def bulk_terms(self, s: Any, uh: Any, w: Any) -> _BulkTerms:
        """:attr:`FEContactProblem.bulk_form` of the prepared step."""
        self._terms = _BulkTerms(self, s, uh, w)
        return self._terms

    def start_at_rest(self, time_s: float) -> None:
        """The undeformed body without fluid pressure at ``time_s`` (an unloaded first time point)."""
        n = len(self.history_field.x.array)
        self.states = [_State(float(time_s), np.zeros(n), np.zeros(3), np.zeros(3), np.zeros(0))]

    def prepare(self, problem: FEContactProblem, time_s: float) -> None:
        """Set the step to ``time_s`` on ``problem`` (its bulk terms, Taylor-Hood, the previous state
        as its warm start). Without a stored state the step is the undrained response to a load
        applied at ``time_s``."""
        previous_dt = None
        if self.states:
            dt = float(time_s) - self.states[-1].time_s
            if not dt > 0.0:
                raise ValueError(f"the biphasic time points must increase: {time_s} s after {self.states[-1].time_s} s")
            if len(self.states) > 1:
                previous_dt = self.states[-1].time_s - self.states[-2].time_s
        else:
            dt = 0.0
        flow_dt, weights = scheme_weights(self.scheme, dt, previous_dt)
        self.step_warnings = []
        if len(weights) == 2 and dt > BDF2_MAX_STEP_RATIO * previous_dt:
            self.step_warnings.append(
                f"the time step grows {dt / previous_dt:.3g} times (BDF2 is zero-stable below {BDF2_MAX_STEP_RATIO:.3f}): "
                "the creep may overshoot (docs/method.md#biphasic-contact); grow the steps more slowly")
        self.constants["flow_dt"].value = flow_dt
        h = self.history_field.x.array
        h[:] = 0.0
        for weight, state in zip(weights, reversed(self.states)):
            h += weight * state.solution
        problem.element = "TH"
        problem.bulk_form = self.bulk_terms
        last = self.states[-1] if self.states else None
        if last is not None and len(last.ut_owned):
            problem.initial_translation_mm = last.translation_mm
            problem.initial_rotation_rad = last.rotation_rad
            problem.initial_field = last.ut_owned

    def solve(self, problem: FEContactProblem, time_s: float, comm: Any = None, progress: Any = None) -> FEContactResult:
        """Solve the prepared step (:meth:`prepare`) and store its state. The drainage set is the
        iterate's; where Newton cycles between drainage sets, it is frozen over each solve
        (module docstring)."""
        from fem_reference.contact import solve_contact

        self.frozen_drainage = None
        passes, warnings = 1, list(self.step_warnings)
        try:
            result = solve_contact(problem, comm, keep_fields=True, progress=progress)
        except FEConvergenceError:
            if self.counter_surface == "porous" or not self.states or self.constants["flow_dt"].value == 0.0:
                raise  # the drainage set plays no part in this step
            result, passes, frozen = self._solve_frozen(problem, comm, progress)
            warnings += frozen
        finally:
            self.frozen_drainage = None
        result.warnings += warnings
        self._commit(float(time_s), result)
        self.drainage_passes.append(passes)
        return result

    def _solve_frozen(self, problem: FEContactProblem, comm: Any, progress: Any) -> tuple[FEContactResult, int, list[str]]:
        """The step with the drainage set frozen over each solve: the previous time point's contact
        set, then each solve's own, until it no longer changes."""
        from fem_reference.contact import solve_contact

        fem, MPI = self.fe["fem"], self.fe["MPI"]
        self.frozen_drainage = fem.Function(self._space)
        self.frozen_drainage.x.array[:] = self.states[-1].solution
        newton = 0
        for passes in range(1, MAX_DRAINAGE_PASSES + 1):
            result = solve_contact(problem, comm, keep_fields=True, progress=progress)
            newton += result.newton_iterations
            self.candidate.x.array[:] = result.fields["solution"].x.array
            changed = self._terms.setup.comm.allreduce(float(fem.assemble_scalar(self._terms.changed_area)), op=MPI.SUM)
            if changed == 0.0:
                break
            self.frozen_drainage.x.array[:] = self.candidate.x.array
            problem.initial_translation_mm = result.bone_displacement_mm.copy()
            problem.initial_rotation_rad = result.bone_rotation_rad.copy()
            problem.initial_field = result.fields["ut_owned"].copy()
        result.newton_iterations = newton
        warnings = [] if changed == 0.0 else [
            f"the drainage set of the contact face still changed after {MAX_DRAINAGE_PASSES} solves: on "
            f"{changed:.3g} mm^2 (of {result.contact_area_mm2:.4g} mm^2 in contact) the fluid boundary condition is "
            "that of the contact state before the last solve"]
        return result, passes, warnings

    def _commit(self, time_s: float, result: FEContactResult) -> None:
        fem, MPI = self.fe["fem"], self.fe["MPI"]
        comm = self._terms.setup.comm
        fluid, total = (comm.allreduce(float(fem.assemble_scalar(f)), op=MPI.SUM)
                        for f in (self._terms.fluid_share, self._terms.total_pressure))
        self.fluid_load_fraction.append(fluid / total if total > 0.0 else 0.0)
        state = _State(time_s, result.fields["solution"].x.array.copy(), result.bone_displacement_mm.copy(),
                       result.bone_rotation_rad.copy(), result.fields["ut_owned"].copy())
        self.states = (self.states + [state])[-2:]
        self._terms = None


@dataclass
class BiphasicContactStep:
    """One time point of :func:`solve_history`: its contact solve and the fluid's share of the
    contact pressure (integral of p over the contact over that of the contact pressure)."""

    time_s: float
    result: FEContactResult
    fluid_load_fraction: float


def solve_history(base: FEContactProblem, times_s: Any, forces_n: Any, permeability_mm4_per_n_s: float,
                  scheme: str = DEFAULT_TIME_SCHEME, counter_surface: str = DEFAULT_COUNTER_SURFACE,
                  drained_tags: tuple[int, ...] = (FREE_TAG,), comm: Any = None) -> list[BiphasicContactStep]:
    """Biphasic contact over a load history (module docstring).

    ``base``: the problem (mesh, the drained matrix's Young's modulus and Poisson's ratio, obstacle,
    free motions, rollers) at every time point, its force replaced by ``forces_n`` (n, 3) at
    ``times_s`` (n,) in s, increasing. A zero force at the first time point starts at rest there
    (loads are linear between time points); a load there starts with the undrained response to it.
    A zero force after that is refused (unloading is not modelled)."""
    from dataclasses import replace

    from fem_reference.contact_setup import materialize_mesh
    from fem_reference.fe_stack import fe_modules

    comm = fe_modules()["MPI"].COMM_WORLD if comm is None else comm
    mesh = materialize_mesh(base, comm)
    history = BiphasicContactHistory(mesh, permeability_mm4_per_n_s, scheme, counter_surface, drained_tags)
    steps = []
    for k, (t, force) in enumerate(zip(np.asarray(times_s, float), np.asarray(forces_n, float))):
        if not np.any(force):
            if k > 0:
                raise ValueError(f"time point {k}: the biphasic contact does not unload (a zero force after the first time point)")
            history.start_at_rest(float(t))
            continue
        problem = replace(base, mesh=mesh, force_n=force)
        history.prepare(problem, float(t))
        result = history.solve(problem, float(t), comm)
        result.fields = None
        steps.append(BiphasicContactStep(float(t), result, history.fluid_load_fraction[-1]))
    return steps
