"""Kelvin-Voigt springs in EDEM (docs/method.md#4-viscoelastic-edem-thesis-chapter-6, thesis eq. 6.13-6.18).

Every spring is a spring and a dashpot in parallel, damping = tau x stiffness: its total force f
and its elastic force e obey f = e + tau de/dt (for a linear spring e = k w, w its compression).
``[viscoelastic] contact_set`` (:data:`CONTACT_SETS`) says how a time point decides which springs
touch:

* ``creeping`` (:class:`CreepingContactSet`, the default): each spring's own compression decides.
  Each time point is one implicit step of f = e + tau de/dt, written as the FE twin writes it,
  f_n = c0 e_n - S_n with S_n = sum_j c_j e_{n-j} (:func:`scheme_weights`, BDF2 by default), and
  the unilateral condition acts on the spring's gap after its own creep. That is one elastic
  contact solve per time point with every spring c0 times stiffer and its force shifted by -S_n
  (the gap shifted by S_n / (c0 k)): :class:`Creep` (docs/method.md, "The contact set from the
  creeping displacement"). Springs out of contact creep back freely (f = 0, e_n = S_n / c0).
* ``frozen`` (:class:`FrozenContactSet`): the thesis's increment H du/dt + K u = T - p with
  H = tau K over a step whose contact set is the quasi-static one under T_k. Within one step
  (t_{k-1} -> t_k, geometry and active set frozen) the load is linear in time, so with
  r(s) = K^-1 (T(s) - p) the increment obeys tau du/ds + u = r(s), u(0) = 0, and every integrator
  returns

      u(dt) = phi K^-1 (T_{k-1} - p) + psi K^-1 (T_k - T_{k-1})

  with weights (phi, psi) that depend only on z = dt / tau:
  - exact: phi = 1 - exp(-z), psi = 1 - phi / z (the closed form of the linear ODE: unconditionally
    stable and exact for loads piecewise linear in time);
  - rk2 (the thesis's Heun step): phi = z - z^2 / 2, psi = z / 2; its creep amplification
    1 - z + z^2 / 2 exceeds 1 in modulus for z > 2, i.e. dt > 2 tau.
  Since the dashpots carry T - (p + K u) at the end of the step, the total spring force (elastic +
  viscous) equals the quasi-static elastic solution under T_k: pressure follows the load.

The EDEM time loop (:func:`edem.solver.run`) holds one :class:`ViscoelasticStepping` per run.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from edem.laws import LinearElements
from edem.mechanics import DOF_NAMES, ShearTerms, UnilateralSolution
from geometries.errors import InputError
from geometries.rowwise import row_dot

#: implicit schemes of the Kelvin-Voigt law, shared with the FE twin (fem_reference.viscoelastic)
TIME_SCHEMES = ("trapezoidal", "bdf2", "backward-euler")
DEFAULT_TIME_SCHEME = "bdf2"


def scheme_weights(scheme: str, dt_s: float, previous_dt_s: float | None, relaxation_time_s: float,
                   ) -> tuple[float, tuple[float, ...], float]:
    """(c0, (c_1, c_2, ...), e) of v_n = c0 u_n - sum_j c_j u_{n-j} - e r_{n-1}, v = u + tau du/dt and
    r = v - u (docs/method.md, "The viscoelastic twin"), for a step dt_s after one of previous_dt_s.

    * BDF2 (second order, L-stable), w = dt_n / dt_{n-1}, a = tau / dt_n: c0 = 1 + a (1 + 2w) / (1 + w),
      c = (a (1 + w), -a w^2 / (1 + w)), e = 0; ``previous_dt_s`` None (the first step): trapezoidal;
    * trapezoidal: c0 = 1 + 2a, c = (2a,), e = 1;
    * backward Euler (first order): c0 = 1 + a, c = (a,), e = 0.

    The weights are consistent (c0 - sum c_j = 1 and the rate enters only through r: a body at
    rest stays at rest).
    """
    if scheme not in TIME_SCHEMES:
        raise ValueError(f"unknown time scheme {scheme!r} (expected {' or '.join(TIME_SCHEMES)})")
    if not (dt_s > 0.0):
        raise ValueError(f"the time step must be > 0, got {dt_s!r} s")
    a = relaxation_time_s / dt_s
    if scheme == "backward-euler":
        return 1.0 + a, (a,), 0.0
    if scheme == "trapezoidal" or previous_dt_s is None:
        return 1.0 + 2.0 * a, (2.0 * a,), 1.0
    w = dt_s / previous_dt_s
    return 1.0 + a * (1.0 + 2.0 * w) / (1.0 + w), (a * (1.0 + w), -a * w * w / (1.0 + w)), 0.0


# ------------------------------------------------------------------------- the thesis's frozen increment

RK2_STABILITY_LIMIT = 2.0  # dt / tau


def integrator_weights(dt_s: float, relaxation_time_s: float, integrator: str) -> tuple[float, float]:
    """(phi, psi) of one step of length dt for the exact or RK2 integrator (module docstring)."""
    if dt_s <= 0.0:
        return 0.0, 0.0  # no time elapses: a step load is carried by the dashpots alone
    z = dt_s / relaxation_time_s
    if integrator == "exact":
        phi = -math.expm1(-z)
        # psi = 1 - (1 - exp(-z)) / z, written to keep its accuracy for small z.
        psi = 1.0 - phi / z if z > 1e-4 else z / 2.0 - z * z / 6.0 + z**3 / 24.0
        return phi, psi
    if integrator == "rk2":
        return z - 0.5 * z * z, 0.5 * z
    raise ValueError(f"unknown integrator {integrator!r}")


def check_rk2_stability(time_s, relaxation_time_s: float, allow_unstable: bool, file: str | None = None) -> list[str]:
    """Refuse RK2 beyond dt > 2 tau (or warn when the scene insists), docs/method.md#4-viscoelastic-edem-thesis-chapter-6."""
    dt = float(np.max(np.diff(time_s), initial=0.0))
    if dt <= RK2_STABILITY_LIMIT * relaxation_time_s:
        return []
    text = (
        f"RK2 is unstable here: the largest time step {dt:g} s exceeds 2 tau = {2 * relaxation_time_s:g} s "
        f"(dt / tau = {dt / relaxation_time_s:.3g})"
    )
    if not allow_unstable:
        raise InputError(
            text,
            file=file,
            key="viscoelastic.integrator",
            expected='integrator = "exact" (unconditionally stable), time steps <= 2 tau, or allow_unstable = true',
        )
    return [text + "; run anyway because viscoelastic.allow_unstable = true"]


# ------------------------------------------------------------------------- the creeping contact set


@dataclass(frozen=True)
class Creep:
    """One time point's Kelvin-Voigt step with the contact set of the creeping displacement.

    Each spring's total force is f_n = c0 e_n - S_n (module docstring). In contact its elastic
    force is the elastic law's at the step's approach, e_n = s(delta), so f_n = c0 s(delta) - S_n:
    the elastic step with every spring c0 times stiffer and its force shifted by -S_n. A law whose
    force is carried from step to step (the threshold law: no geometric gap) starts a spring that
    is out of contact at its gap gamma (mm), s(delta) = e - k (gamma - delta). The ligaments stay
    elastic.
    """

    scale: float  # c0
    history_force_n: np.ndarray  # (3, n_springs) S_n = sum_j c_j E_{n-j} of the elastic force vectors E
    gap_mm: np.ndarray  # (n_springs,) gamma: each spring's gap at the step's start (a carried law's; else zeros)

    def normal_history_n(self, normals: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
        """S_n along the springs' normals (m, 3) at the pose: of the springs ``index`` (all: None)."""
        history = self.history_force_n if index is None else self.history_force_n.take(index, axis=1)
        return row_dot(history.T, normals)

    def law(self, step) -> LinearElements:
        """The element law (springs then ligaments) of the creeping step of ``step`` (an
        :class:`edem.beds.ContactStep`; its law the elastic one at the pose)."""
        law, n_c = step.law, step.n_candidates
        if not isinstance(law, LinearElements):
            raise ValueError("the creeping contact set takes linear laws only (CreepingContactSet refuses the others)")
        index, normals = step.geometry.candidate_index, step.directions[:n_c, :3]
        offset, stiffness = law.offset_n.copy(), law.stiffness_n_per_mm.copy()
        spring_stiffness = stiffness[:n_c]
        offset[:n_c] = self.scale * (offset[:n_c] - spring_stiffness * self.gap_mm.take(index)) - self.normal_history_n(normals, index)
        stiffness[:n_c] = self.scale * spring_stiffness
        return LinearElements(offset, stiffness)

    def shear(self, shear: ShearTerms | None, index: np.ndarray, normals: np.ndarray) -> ShearTerms | None:
        """The candidates' (``index``, their ``normals`` (c, 3)) shear springs in the creeping step:
        c0 k_s, and the stored tangential force c0 e_t - S_t."""
        if shear is None:
            return None
        history = self.history_force_n.take(index, axis=1).T
        tangential = history - row_dot(history, normals)[:, None] * normals
        return replace(shear, stiffness_n_per_mm=self.scale * shear.stiffness_n_per_mm, stored_force_n=self.scale * shear.stored_force_n - tangential)


def touch_motion(free_gap_mm: np.ndarray, rows: np.ndarray, ligament_rows: np.ndarray, ligament_law: LinearElements,
                 direction: np.ndarray | None) -> np.ndarray | None:
    """The force-free pose of an unloaded time point: u (6,), or None where there is none.

    Nothing carries a force at u = s (d, 0) when every spring's gap stays open, free_gap - g . u >= 0,
    and every ligament stays slack, offset + k l . u <= 0. The pose is the largest such s along
    ``direction`` d (3,) (the last load's, in the free translations), where the body touches the
    cartilage creeping back: the limit of a vanishing load along d, as the FE twin takes it
    (docs/method.md, "The contact set from the creeping displacement"). Without a direction (no
    load yet), s = 0 if that is force-free. ``free_gap_mm`` (n_c,): the springs' gaps at u = 0 with
    no force anywhere (negative: an overlap); ``rows`` (n_c, 6) and ``ligament_rows`` (n_l, 6).
    """
    motion = np.zeros(6)
    if direction is not None:
        motion[:3] = direction
    # Each element is force-free for a + b s <= 0: springs a = -gap (mm), ligaments a = tension at u = 0 (N).
    parts = ((-free_gap_mm, rows @ motion), (ligament_law.offset_n, ligament_law.stiffness_n_per_mm * (ligament_rows @ motion)))
    low, high = -np.inf, np.inf
    for a, b in parts:
        # (1e-12 of the largest term: a touching spring or a slack ligament at round-off passes)
        slack = 1e-12 * max(float(np.abs(a).max(initial=0.0)), float(np.abs(b).max(initial=0.0)), 1e-300)
        fixed = np.abs(b) <= slack
        if np.any(a[fixed] > slack):
            return None
        bound = -a[~fixed] / b[~fixed]
        up = b[~fixed] > 0.0
        high = min(high, float(bound[up].min(initial=np.inf)))
        low = max(low, float(bound[~up].max(initial=-np.inf)))
    if direction is None:
        low = high = 0.0 if low <= 0.0 <= high else math.nan
    s = high if math.isfinite(high) else max(low, 0.0)
    if not math.isfinite(s) or low > s + 1e-12 * abs(s):
        return None
    return s * motion


class ViscoelasticStepping(ABC):
    """How a run's Kelvin-Voigt springs step through time (:data:`CONTACT_SETS`).

    The EDEM time loop asks, at each time point k: :meth:`prepare` (the contact problem to solve,
    from the elastic one), :meth:`solve` (its solution by the bed), :meth:`increment` (M's motion
    u (6,) and the elastic element forces (n_c + n_l,) to commit) and :meth:`commit` (the elastic
    force vectors (3, n_springs) of every spring, as stored for the next time point).
    ``warnings``: what the run says about the scheme.
    """

    #: the value of ``[viscoelastic] contact_set``
    name: ClassVar[str]
    #: its values of ``[viscoelastic] integrator``, the first the default
    integrators: ClassVar[tuple[str, ...]]

    def __init__(self, scene: Any, loads: np.ndarray) -> None:
        self.viscous = scene.viscoelastic
        self.time_s = np.asarray(scene.load.time_s, float)
        self.warnings: list[str] = []

    def prepare(self, k: int, step):
        """The contact problem of time point k (an :class:`edem.beds.ContactStep`) from the elastic one."""
        return step

    def solve(self, bed, step, load: np.ndarray) -> UnilateralSolution:
        """The prepared problem's solution by the bed under ``load`` (6,)."""
        return bed.solve(step, load)

    @abstractmethod
    def increment(self, bed, step, solution: UnilateralSolution, k: int, loads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u (6,), elastic element forces (n_c + n_l,)) of time point k."""

    def commit(self, stored: np.ndarray, in_contact: np.ndarray) -> np.ndarray:
        """The elastic force vectors (3, n_springs) to keep: ``stored`` those of the springs in
        contact (``in_contact`` (n_springs,)), zero elsewhere."""
        return stored


class FrozenContactSet(ViscoelasticStepping):
    """The thesis's increment (eq. 6.18, module docstring): the set frozen at the quasi-static one."""

    name = "frozen"
    integrators = ("exact", "rk2")

    def __init__(self, scene, loads):
        super().__init__(scene, loads)
        if self.viscous.integrator == "rk2":
            self.warnings += check_rk2_stability(self.time_s, self.viscous.relaxation_time_s, self.viscous.allow_unstable, scene.source)

    def increment(self, bed, step, solution, k, loads):
        dt = float(self.time_s[k] - self.time_s[k - 1]) if k else 0.0
        previous = loads[k - 1] if k else np.zeros(6)
        weights = integrator_weights(dt, self.viscous.relaxation_time_s, self.viscous.integrator)
        return bed.viscoelastic_increment(step, solution, previous, loads[k], weights)


class CreepingContactSet(ViscoelasticStepping):
    """Kelvin-Voigt springs whose own creeping compression decides the contact (module docstring).

    State: the elastic force vectors E of the last two time points (n_springs each), and for a law
    whose force is carried (the threshold law) each spring's gap. The body is at rest at the first
    time point: a load there has been held since long before (the elastic solution, as in the FE
    twin). An unloaded time point (no load along the free DOFs) has no contact force: the
    cartilage creeps back and M follows it without force (:func:`touch_motion`), unless the
    ligaments hold it against the cartilage (then the bed's solve).
    """

    name = "creeping"
    integrators = ("bdf2", "backward-euler")

    def __init__(self, scene, loads):
        super().__init__(scene, loads)
        law = scene.cartilage.spring_law
        if law.nonlinear:
            raise InputError(f"the creeping contact set takes linear springs; the {law.name} law is not linear", file=scene.source,
                             key="viscoelastic.contact_set", expected='law = "gap" or "threshold", or contact_set = "frozen" (the thesis\'s increment)')
        # A law whose force is carried from step to step (threshold) has no geometric gap: it is kept here.
        self.carried = law.thin_layer == "carried"
        self.free = np.array([d not in scene.fixed_dofs for d in DOF_NAMES])
        self.elastic: list[np.ndarray] = []  # E_{n-1}, E_{n-2}, ... (3, n_springs) each, newest first
        self.gap_mm = np.zeros(scene.spring_area_mm2.shape[0])
        self.direction: np.ndarray | None = None  # the last load's, in the free translations (unit)
        self.creep: Creep | None = None  # the time point prepared
        if np.any(np.asarray(loads[0])[self.free]):
            self.warnings.append(
                "the first time point carries a load: the Kelvin-Voigt springs start from the elastic solution under it "
                "(a load held since long before, as the FE twin starts); start the load history at zero for a creep "
                "from the unloaded body")

    def prepare(self, k, step):
        if k == 0:  # at rest before t_0: the elastic step (c0 = 1, no history)
            c0, history = 1.0, np.zeros((3, self.gap_mm.shape[0]))
        else:
            previous = float(self.time_s[k - 1] - self.time_s[k - 2]) if k > 1 else None
            c0, weights, _ = scheme_weights(self.viscous.integrator, float(self.time_s[k] - self.time_s[k - 1]), previous,
                                            self.viscous.relaxation_time_s)
            # (the trapezoidal first step's rate term e r_0 vanishes: the body is at rest at t_0)
            history = sum(c * e for c, e in zip(weights, self.elastic))
        self.creep = Creep(c0, history, self.gap_mm)
        index, normals = step.geometry.candidate_index, step.directions[: step.n_candidates, :3]
        return replace(step, creep=self.creep, shear=self.creep.shear(step.shear, index, normals))

    def solve(self, bed, step, load):
        if not np.any(load[self.free]):
            solution = bed.force_free(step, self.direction)
            if solution is not None:
                return solution
        force = np.where(self.free[:3], load[:3], 0.0)
        size = float(np.linalg.norm(force))
        if size > 0.0:
            self.direction = force / size
        return bed.solve(step, load)

    def increment(self, bed, step, solution, k, loads):
        n_c = step.n_candidates
        force = np.where(solution.active, solution.element_force_n, 0.0)
        elastic = force.copy()
        history = self.creep.normal_history_n(step.directions[:n_c, :3], step.geometry.candidate_index)
        elastic[:n_c] = np.where(solution.active[:n_c], (force[:n_c] + history) / self.creep.scale, 0.0)
        if self.carried:  # (a spring that stops being a candidate leaves the layer: it starts touching when it comes back)
            self.gap_mm = np.zeros_like(self.gap_mm)
            self.gap_mm[step.geometry.candidate_index] = bed.spring_gaps_mm(step, solution)
        return solution.displacement, elastic

    def commit(self, stored, in_contact):
        # out of contact (f = 0): e_n = S_n / c0, the spring creeps back with its dashpot
        stored[:, ~in_contact] = self.creep.history_force_n[:, ~in_contact] / self.creep.scale
        self.elastic = [stored] + self.elastic[:1]
        return stored


#: the ways a time point decides the Kelvin-Voigt springs' contact set, by ``[viscoelastic] contact_set``
CONTACT_SETS: dict[str, type[ViscoelasticStepping]] = {s.name: s for s in (CreepingContactSet, FrozenContactSet)}
#: the contact set of a scene that names none
DEFAULT_CONTACT_SET = CreepingContactSet.name


def integrator_problem(contact_set: str, integrator: str) -> str | None:
    """Why ``integrator`` cannot go with ``contact_set`` (None: it can)."""
    if contact_set not in CONTACT_SETS:
        return f"unknown contact set {contact_set!r} (expected {' or '.join(CONTACT_SETS)})"
    allowed = CONTACT_SETS[contact_set].integrators
    if integrator in allowed:
        return None
    owner = next((name for name, each in CONTACT_SETS.items() if integrator in each.integrators), None)
    hint = f' (it is the {owner} contact set\'s: contact_set = "{owner}" with it)' if owner else ""
    return f'integrator {integrator!r} does not step contact_set = "{contact_set}"{hint}; its integrators: {", ".join(allowed)}'


def viscoelastic_stepping(scene: Any, loads: np.ndarray) -> ViscoelasticStepping:
    """The stepping of ``scene``'s ``[viscoelastic]`` (an :class:`edem.scene.Scene`; ``loads`` (n, 6)
    its applied loads)."""
    return CONTACT_SETS[scene.viscoelastic.contact_set](scene, loads)
