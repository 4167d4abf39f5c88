"""Kelvin-Voigt FE contact over time: the viscoelastic twin of EDEM's Kelvin-Voigt springs (docs/method.md#6-the-fe-reference-and-its-discrete-twins).

The continuum is sigma = C : (eps(u) + tau eps(du/dt)) = C : eps(v) with v = u + tau du/dt, C the
elastic tensor and tau the springs' relaxation time. An implicit scheme writes the rate at t_n from
the displacements it has, so that

    v_n = c0 u_n - h_n,        h_n = sum_j c_j u_{n-j} + e r_{n-1},   r = v - u = tau du/dt

* BDF2 (the default; second order, L-stable, variable step, w = dt_n / dt_{n-1}):
  c0 = 1 + a (1 + 2w) / (1 + w), h_n = a (1 + w) u_{n-1} - a w^2 / (1 + w) u_{n-2}, its first step
  trapezoidal. Its three-point rate straddles a kink of the load: after a steep one (a load
  raised in one step) its local error is first order there (2.5 % of the creep at dt = tau/8);
* trapezoidal: tau (u_n - u_{n-1}) / dt = (r_n + r_{n-1}) / 2, so c0 = 1 + 2a,
  h_n = 2a u_{n-1} + r_{n-1}, a = tau / dt_n: second order through the load's kinks (EDEM reads a
  load history as linear between time points, so its kinks fall on time points), but it does
  not damp its rate: where the contact set changes the rate r, hence the pressure, oscillates
  from step to step without decay (the peak alternating 3.4 / 5.2 MPa for 5 tau on the cylinder
  layer), so it suits contacts whose set does not change (confined compression);
* backward Euler (first order): c0 = 1 + a, h_n = a u_{n-1}.

Each time point is then an elastic contact problem for v: div(C : eps(v_n)) balances the load at
t_n, the bonded face moves rigidly with v's rigid motion D_n = c0 d_n - (h_n's rigid part), and
the frictionless contact condition, which acts on u_n = (v_n + h_n) / c0,

    gap + u_n . nu >= 0   <=>   c0 gap + h_n . nu + v_n . nu >= 0,

is the elastic one with the shifted gap c0 gap + h_n . nu, and Nitsche's penalty gamma on u is
gamma / c0 on v (:func:`fem_reference.contact.solve_contact`), so a steady state solves the elastic
discrete problem's pressure. The contact pressure is the traction of C : eps(v_n), the total
(elastic + viscous) stress. :func:`fem_reference.contact.solve_contact` solves it unchanged
(:class:`fem_reference.problem.FEContactProblem` ``gap_scale`` = c0, ``gap_history`` = h_n).

An unloaded time point has no contact force: v_n is the rigid motion D_n, so the deformation
u_n - d_n = (h_n - h_n's rigid part) / c0 creeps back freely, and the bone follows the layer,
touching it with no force (D_n the touch distance of the shifted gap along the last load's
direction: the limit of a vanishing load).

Two deformable layers (:mod:`fem_reference.two_body`, F's layer a
:class:`~fem_reference.problem.DeformableCounterpart` in the same mesh) creep with the same tau:
h_n holds both layers' histories, the shifted gap is c0 gap + (h_n - h_n^F) . nu with h_n^F F's
history at the paired points, and unloaded, F's layer creeps back on its held bone (v_n = 0 there).

The body starts at rest at the first time point. With a load there the FE starts from the elastic
solution under it (a load held long before t_0), where EDEM starts undeformed with the dashpots
carrying it: :func:`first_load_warning` says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from edem.viscoelastic import DEFAULT_TIME_SCHEME, TIME_SCHEMES, scheme_weights  # noqa: F401 (the FE's schemes: shared with EDEM)
from fem_reference.problem import DeformableCounterpart, FEContactProblem, FEContactResult

def first_load_warning(force_n: np.ndarray) -> list[str]:
    """The FE and EDEM start differently under a load at the first time point (module docstring)."""
    if not np.any(force_n):
        return []
    return ["the first time point carries a load: the viscoelastic FE starts from the elastic solution under it "
            "(a load held since long before), EDEM from the undeformed bed with the dashpots carrying it; "
            "the two differ until that start has crept away (several tau): start the load history at zero to compare them"]


@dataclass
class _State:
    time_s: float
    u: Any  # dolfinx Function (vector Lagrange of the displacement degree): u_n
    translation_mm: np.ndarray  # (3,) the bone's, d_n
    rotation_rad: np.ndarray  # (3,) the bone's small rotation about G
    rate: Any  # r_n = v_n - u_n = tau du/dt (a Function of the same space)
    rate_translation_mm: np.ndarray  # its rigid parts
    rate_rotation_rad: np.ndarray


@dataclass
class KelvinVoigtHistory:
    """The displacement history of a Kelvin-Voigt FE run on one mesh (module docstring).

    ``mesh``: the :class:`fem_reference.problem.FEMesh` every time point is solved on; ``degree``:
    the displacement degree (1 for P1, 2 for P2 and Taylor-Hood).
    """

    mesh: Any
    degree: int
    relaxation_time_s: float
    scheme: str = DEFAULT_TIME_SCHEME
    states: list[_State] = field(default_factory=list)
    last_direction: np.ndarray | None = None  # the last load's direction in the free translations
    last_v: dict | None = None  # the last solve's v (translation, rotation, ut_owned): warm start

    def __post_init__(self) -> None:
        from fem_reference.fe_stack import fe_modules

        if self.scheme not in TIME_SCHEMES:
            raise ValueError(f"unknown time scheme {self.scheme!r}")
        self._fem = fe_modules()["fem"]
        self._space = self._fem.functionspace(self.mesh.mesh, ("Lagrange", self.degree, (3,)))

    def _function(self) -> Any:
        return self._fem.Function(self._space)

    def start_at_rest(self, time_s: float) -> None:
        """u = 0 at the first time point (an unloaded body)."""
        self.states = [_State(time_s, self._function(), np.zeros(3), np.zeros(3), self._function(), np.zeros(3), np.zeros(3))]

    def _history(self, time_s: float) -> tuple[float, Any, np.ndarray, np.ndarray]:
        """(c0, h_n = sum_j c_j u_{n-j} + e r_{n-1}, its rigid translation and rotation) of the
        step to ``time_s`` from the stored states."""
        last = self.states[-1]
        previous = last.time_s - self.states[-2].time_s if len(self.states) > 1 else None
        c0, coefficients, e = scheme_weights(self.scheme, time_s - last.time_s, previous, self.relaxation_time_s)
        h = self._function()
        h.x.array[:] = e * last.rate.x.array
        d, q = e * last.rate_translation_mm, e * last.rate_rotation_rad
        for c, state in zip(coefficients, reversed(self.states)):
            h.x.array[:] += c * state.u.x.array
            d = d + c * state.translation_mm
            q = q + c * state.rotation_rad
        return c0, h, d, q

    def _push(self, time_s: float, u: Any, d: np.ndarray, q: np.ndarray, v: Any, vd: np.ndarray, vq: np.ndarray) -> None:
        """Store u_n and its rate r_n = v_n - u_n (v given as a Function and its rigid parts)."""
        v.x.array[:] -= u.x.array
        self.states = (self.states + [_State(time_s, u, d, q, v, vd - d, vq - q)])[-2:]

    def prepare(self, problem: FEContactProblem, time_s: float) -> tuple[float, np.ndarray, np.ndarray]:
        """Set the shifted gap of the step to ``time_s`` on ``problem`` (and the previous v as its
        warm start); returns (c0, h's translation, h's rotation) for :meth:`commit`.

        Without a stored state the step is elastic (the first time point under a load)."""
        if not self.states:
            problem.gap_scale, problem.gap_history = 1.0, None
            return 1.0, np.zeros(3), np.zeros(3)
        c0, h, hd, hq = self._history(time_s)
        problem.gap_scale, problem.gap_history = c0, h
        if self.last_v is not None:
            problem.initial_translation_mm = self.last_v["t"]
            problem.initial_rotation_rad = self.last_v["q"]
            problem.initial_field = self.last_v["ut"]
        return c0, hd, hq

    def commit(self, time_s: float, result: FEContactResult, c0: float, hd: np.ndarray, hq: np.ndarray,
               problem: FEContactProblem) -> tuple[np.ndarray, np.ndarray]:
        """Store u_n = (v_n + h_n) / c0 from a solve of the prepared problem (``keep_fields``) and
        return the bone's translation and rotation d_n, q_n (the result's are v's)."""
        solution = result.fields["solution"]
        v = self._function()
        v.interpolate(solution.sub(0) if result.element == "TH" else solution)
        u = self._function()
        u.x.array[:] = v.x.array
        h = problem.gap_history
        if h is not None:
            u.x.array[:] += h.x.array
        u.x.array[:] /= c0
        d = (result.bone_displacement_mm + hd) / c0
        q = (result.bone_rotation_rad + hq) / c0
        self._push(time_s, u, d, q, v, result.bone_displacement_mm, result.bone_rotation_rad)
        dirs = result.free_directions
        along = dirs.T @ (dirs @ result.applied_force_n)
        if np.linalg.norm(along) > 0:
            self.last_direction = along / np.linalg.norm(along)
        self.last_v = {"t": result.bone_displacement_mm.copy(), "q": result.bone_rotation_rad.copy(),
                       "ut": result.fields["ut_owned"].copy()}
        return d, q

    def relax(self, time_s: float, obstacle: Any, contact_tag: int) -> tuple[np.ndarray, np.ndarray]:
        """An unloaded time point (module docstring): the deformation creeps back and the bone
        follows the layer without force. Returns its translation and rotation."""
        from fem_reference.fe_stack import fe_modules

        mods = fe_modules()
        fem, MPI = mods["fem"], mods["MPI"]
        c0, h, hd, hq = self._history(time_s)
        D = np.zeros(3)
        mesh = self.mesh.mesh
        if self.last_direction is not None:
            fdim = mesh.topology.dim - 1
            Q = fem.functionspace(mesh, ("Lagrange", self.degree))
            dofs = fem.locate_dofs_topological(Q, fdim, self.mesh.facet_tags.find(contact_tag))
            points = Q.tabulate_dof_coordinates()[dofs]
            gap, normal = obstacle.gap_and_normal(points)
            relative = h.x.array.reshape(-1, 3)[dofs] - self._paired_history(obstacle, Q, h, points)
            shifted = c0 * gap + np.einsum("ij,ij->i", relative, normal)
            s = normal @ self.last_direction
            approaching = s < -1e-9
            local = float(np.min(shifted[approaching] / -s[approaching])) if approaching.any() else np.inf
            touch = mesh.comm.allreduce(local, op=MPI.MIN)
            if np.isfinite(touch):
                D = touch * self.last_direction
        v = self._function()
        v.x.array.reshape(-1, 3)[:] = D
        if isinstance(obstacle, DeformableCounterpart):  # F's layer stays on its held bone: v = 0 there
            cells = self.mesh.cell_tags.find(obstacle.cell_tag)
            v.x.array.reshape(-1, 3)[np.unique(self._space.dofmap.list[cells])] = 0.0
        u = self._function()
        u.x.array[:] = (h.x.array + v.x.array) / c0
        d, q = (D + hd) / c0, hq / c0
        self._push(time_s, u, d, q, v, D, np.zeros(3))
        self.last_v = None  # v was rigid: no warm start for the next loaded step
        return d, q

    def _paired_history(self, obstacle: Any, Q: Any, h: Any, points: np.ndarray) -> np.ndarray:
        """F's history h at the points of F's contact face paired with ``points`` (n, 3), nodes of
        M's contact face (a Lagrange space ``Q`` of the history's degree locates F's nodes): zero
        against a rigid obstacle."""
        if not isinstance(obstacle, DeformableCounterpart):
            return np.zeros((len(points), 3))
        from scipy.spatial import cKDTree

        from fem_reference.fe_stack import fe_modules

        mesh = self.mesh.mesh
        fixed = fe_modules()["fem"].locate_dofs_topological(Q, mesh.topology.dim - 1, self.mesh.facet_tags.find(obstacle.contact_tag))
        coords = np.concatenate(mesh.comm.allgather(Q.tabulate_dof_coordinates()[fixed]))
        values = np.concatenate(mesh.comm.allgather(h.x.array.reshape(-1, 3)[fixed]))
        stencil, weights = obstacle.stencil(points, self.degree)
        used = weights != 0.0
        out = np.zeros((len(points), 3))
        if used.any():
            _, j = cKDTree(coords).query(stencil[used])
            np.add.at(out, np.nonzero(used)[0], weights[used][:, None] * values[j])
        return out


@dataclass
class KelvinVoigtStep:
    """One time point of :func:`solve_history`: the bone's motion d_n, q_n and the solve of v_n,
    whose pressure, area and contact force are the time point's (None at an unloaded one)."""

    time_s: float
    translation_mm: np.ndarray
    rotation_rad: np.ndarray
    result: FEContactResult | None


def solve_history(base: FEContactProblem, times_s: Any, forces_n: Any, relaxation_time_s: float,
                  scheme: str = DEFAULT_TIME_SCHEME, comm: Any = None) -> list[KelvinVoigtStep]:
    """Kelvin-Voigt FE contact over a load history (module docstring), the body at rest before.

    ``base``: the problem (mesh, material, obstacle, free motions) at every time point, its
    force replaced by ``forces_n`` (n, 3) at ``times_s`` (n,) in s, increasing.
    """
    from dataclasses import replace

    from fem_reference.contact import solve_from_warm_start
    from fem_reference.contact_setup import materialize_mesh
    from fem_reference.fe_stack import fe_modules

    MPI = fe_modules()["MPI"]
    comm = MPI.COMM_WORLD if comm is None else comm
    mesh = materialize_mesh(base, comm)
    history = KelvinVoigtHistory(mesh, 1 if base.resolved_element() == "P1" else 2, relaxation_time_s, scheme)
    steps = []
    for k, (t, force) in enumerate(zip(np.asarray(times_s, float), np.asarray(forces_n, float))):
        if not np.any(force):
            if k == 0:
                history.start_at_rest(float(t))
                steps.append(KelvinVoigtStep(float(t), np.zeros(3), np.zeros(3), None))
            else:
                d, q = history.relax(float(t), base.obstacle, base.contact_tag)
                steps.append(KelvinVoigtStep(float(t), d, q, None))
            continue
        problem = replace(base, mesh=mesh, force_n=force)
        c0, hd, hq = history.prepare(problem, float(t))
        result = solve_from_warm_start(problem, comm)
        d, q = history.commit(float(t), result, c0, hd, hq, problem)
        result.fields = None
        steps.append(KelvinVoigtStep(float(t), d, q, result))
    return steps
