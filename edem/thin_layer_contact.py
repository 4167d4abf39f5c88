"""Unilateral contact of a rigid body on the coupled thin layer (``[cartilage] coupling = "thin-layer"``).

The springs of ``edem.mechanics`` are replaced by a layer whose surface deflection w (mm, per
candidate spring) answers the spring forces f (N) through the symmetric positive definite
compliance of ``edem.thin_layer``: w = C f. The rigid motion u (6 DOFs) approaches spring j by
g_j . u, so the layer must be compressed by d_j(u) = d0_j + g_j . u (d0: the overlap before the
increment: t - h for the gap law, C f_carried for the threshold law's EDEM push-back, 0 in DEM;
the push-back is solved for without forming C f_carried, see "Carried forces" below).
Contact is the complementarity problem

    f >= 0,   y = C f - d(u) >= 0,   f . y = 0,   sum_j f_j g_j + ligaments + shear = T,

the KKT system of the convex quadratic programme min 1/2 f.C f - f.d0 over f >= 0, sum f g = T
(u is the multiplier of the balance). It is solved by the primal-dual active set method
(semismooth Newton on min(f, k y) = 0): for a set I of springs in contact, f_N = 0 and
w_I = d_I(u), which with the auxiliary vertex fields z = (sigma H)^-1 Z f of the compliance's
smoothing terms (``LayerCompliance``: one for the Pade, two for the two-pole symbol) is the
sparse system

    f_I = Lam (d0_I + D_I u - Z_I^T z),   (sigma H + Z_I Lam Z_I^T) z = Z_I Lam (d0_I + D_I u),

Lam = diag(A / c_loc)_I. One sparse factorisation of the vertex matrix per iteration gives f_I and
z as affine functions of u (seven right-hand sides), so balance is a 6 x 6 solve with the coupled
contact stiffness D_I^T df_I/du; then I is updated: springs with f_j <= 0 leave, springs where the
surface would penetrate (y_j < 0, including where the layer bulges outside the contact) enter.
For C with non-positive off-diagonal entries (nu > 1/4: an M-matrix) this converges in a few
iterations. Ligaments (tension-only) and the shear springs enter the 6 x 6 as in the spring bed.
A nonlinear law (gap-log) adds to w its columns' excess e(f) over the linear column
(``ContactLaw.column_excess_mm``); each iteration linearises it at the previous forces, which
changes Lam and d0 only, so the same factorisation serves (Newton on the same active set).

Carried forces
--------------
For the threshold law's EDEM push-back d0 = o + C c (c: the forces f_carried committed at the
previous step, o a geometric overlap, 0 there), forming C c needs H^-1 Z c, a factorisation of
sigma H alone besides the contact matrix's. The solve works instead on the increments
delta = f - c and zeta = z - z_c, z_c = (sigma H)^-1 Z c, over the stored state, where the carried
forces' own deflection C c cancels from both sides of w_I = d_I(u):

    local_I delta_I + Z_I^T zeta = o_I + D_I u,   sigma H zeta = Z delta,   delta_N = -c_N,

(f_N = 0 out of contact). Eliminating delta_I = Lam (o_I + D_I u - Z_I^T zeta),

    (sigma H + Z_I Lam Z_I^T) zeta = Z_I Lam (o_I + D_I u) - Z_N c_N,   f_I = c_I + Lam (o_I + D_I u - Z_I^T zeta),

the same matrix as above, with the carried forces of the springs that left the contact as one
more load in the u-free right-hand side: the same factorisation serves, and while every spring
that carried a force stays in contact (c_N = 0, as in the viscoelastic increment, whose set holds
them) that column is Lam o_I alone (no solve where o = 0). The gap out of contact is
y_N = C delta - o - D u = -local_N c_N + Z_N^T zeta - o_N - D_N u; the deflection reported is
w - C c = C delta, the layer's deflection over the push-back (C c itself would need the extra
factorisation). A nonlinear column linearised at f0 as (local + slope) f + shift puts
o - shift - slope c in place of o (the linear part of the push-back still cancels).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from geometries.errors import InputError, SolverError
from edem.laws import LinearElements
from edem.mechanics import DOF_NAMES, ShearTerms, UnilateralSolution, _regular_solve, singular_stiffness_error, unrestrained_dofs
from edem.thin_layer import LayerCompliance, SurfaceMesh, layer_compliance
from edem.viscoelastic import touch_motion


@dataclass
class ThinLayerSolution(UnilateralSolution):
    """The unilateral solution plus the layer's surface: deflection and gap (KKT figures)."""

    deflection_mm: np.ndarray = None  # (n_c,) w = C f at the candidate springs
    gap_mm: np.ndarray = None  # (n_c,) y = w - d(u): 0 in contact, >= 0 out of contact
    max_penetration_mm: float = 0.0  # max(-y) over the springs out of contact (<= round-off)


@dataclass(frozen=True)
class ActiveSystem:
    """Spring forces of the contact set I as affine functions of u: f_I = F0 + F1 u (module docstring).

    u is over the free DOFs only (p of them): a fixed DOF never moves, so its columns are never
    formed (on the stances, with four DOFs fixed, that halves the arrays of every spring).
    """

    active: np.ndarray  # (n_c,) bool
    force0_n: np.ndarray  # (n_I,)
    force_per_mm: np.ndarray  # (n_I, p)
    nonlocal0_mm: np.ndarray  # (n_c,) the smoothing terms' deflection Z^T z at every spring at u = 0 (LayerCompliance)
    nonlocal_per_mm: np.ndarray  # (n_c, p)
    local_mm_per_n: np.ndarray  # (n_c,) the local compliance it was built with
    active_rows: np.ndarray  # (n_I, p) the rows of the springs in contact
    carried_force_n: np.ndarray | None = None  # (n_c,) c: f and z are then over the stored state (module docstring)

    @staticmethod
    def build(
        layer: LayerCompliance, rows: np.ndarray, overlap_mm: np.ndarray, active: np.ndarray, local_mm_per_n: np.ndarray | None = None,
        carried_force_n: np.ndarray | None = None,
    ) -> "ActiveSystem":
        """``rows`` (n_c, p): the springs' rows g_j over the free DOFs. ``local_mm_per_n`` (n_c,):
        the local compliance, the layer's unless a nonlinear column is linearised
        (``solve_thin_layer``). ``carried_force_n`` (n_c,): the forces c whose push-back C c adds
        to ``overlap_mm`` (module docstring, "Carried forces"); the vertex fields are then the
        increments zeta over z_c."""
        local = layer.local_mm_per_n if local_mm_per_n is None else local_mm_per_n
        lam = 1.0 / local[active]
        active_rows = rows[active]
        forces = np.empty((lam.shape[0], 1 + rows.shape[1]))  # the u-free column, then one per free DOF
        forces[:, 0] = overlap_mm[active]
        forces[:, 1:] = active_rows
        forces *= lam[:, None]
        nonlocal_mm = None  # Z^T z at every spring (n_c, 1 + p)
        if layer.coupled:
            # Z_I Lam Z_I^T as Z diag(Lam on I, 0 elsewhere) Z^T.
            weight = np.zeros(active.shape[0])
            weight[active] = lam
            solve = layer.factorise_coupled(weight)
            # A zero column (DEM: no overlap before the increment) needs no solves.
            nonzero = np.any(forces, axis=0)
            released = None if carried_force_n is None else np.where(active, 0.0, carried_force_n)
            if released is not None:
                nonzero[0] = nonzero[0] or np.any(released)
            nonzero = np.flatnonzero(nonzero)
            if nonzero.size:
                loads = np.zeros((active.shape[0], nonzero.size))
                loads[active] = forces[:, nonzero]
                if released is not None and nonzero[0] == 0:
                    loads[:, 0] -= released  # -Z_N c_N joins the u-free column
                # Every spring's row, then those in contact: cheaper than cutting Z^T's rows.
                solved = layer.z_t @ solve(layer.z @ loads)
                if nonzero.size == forces.shape[1]:  # (the usual case: no column gathers)
                    nonlocal_mm = solved
                    forces -= lam[:, None] * solved[active]
                else:
                    nonlocal_mm = np.zeros((active.shape[0], forces.shape[1]))
                    nonlocal_mm[:, nonzero] = solved
                    forces[:, nonzero] -= lam[:, None] * solved[active]
        if nonlocal_mm is None:
            nonlocal_mm = np.zeros((active.shape[0], forces.shape[1]))
        if carried_force_n is not None:
            forces[:, 0] += carried_force_n[active]
        return ActiveSystem(active, forces[:, 0], forces[:, 1:], nonlocal_mm[:, 0], nonlocal_mm[:, 1:], local, active_rows, carried_force_n)

    def forces(self, u: np.ndarray) -> np.ndarray:
        """f_I (n_I,) under the free DOFs' motion u (p,)."""
        return self.force0_n + self.force_per_mm @ u

    def deflection(self, layer: LayerCompliance, u: np.ndarray, force_n: np.ndarray) -> np.ndarray:
        """w = C f at every candidate for the forces f (n_c,) of this set under u (p,) (local part
        as built); with carried forces c, w - C c (module docstring, "Carried forces")."""
        w = self.local_mm_per_n * force_n
        if self.carried_force_n is not None:
            w = w - layer.local_mm_per_n * self.carried_force_n
        return w + self.nonlocal0_mm + self.nonlocal_per_mm @ u

    def stiffness(self) -> np.ndarray:
        """Coupled contact stiffness D_I^T dF/du (p, p) over the free DOFs, symmetrised against round-off."""
        k = self.active_rows.T @ self.force_per_mm
        return 0.5 * (k + k.T)

    def pushback(self) -> np.ndarray:
        """D_I^T F0 (p,): the generalised force of the set at u = 0."""
        return self.active_rows.T @ self.force0_n


def _others(ligament_rows, ligament_law, ligament_active, shear, active):
    """Stiffness (6, 6) and generalised force at u = 0 (6,) of the active ligaments and shear springs."""
    c = ligament_law.stiffness_n_per_mm * ligament_active
    k = ligament_rows.T @ (ligament_rows * c[:, None])
    f0 = ligament_rows.T @ (ligament_law.offset_n * ligament_active)
    if shear is not None:
        k = k + shear.stiffness(active)
        f0 = f0 + shear.generalised_force(np.zeros(6), active)
    return k, f0


def _linearised(layer: LayerCompliance, column: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], force_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A nonlinear column linearised at the forces (n,) N: w(f) ~ (local + slope) f + nonlocal f + shift.
    Returns (local + slope (n,) mm/N, shift (n,) mm)."""
    excess, slope = column(force_n)
    return layer.local_mm_per_n + slope, excess - slope * force_n


def _offset(layer: LayerCompliance, overlap_mm: np.ndarray, shift, local: np.ndarray | None, pushback_force_n: np.ndarray | None) -> np.ndarray:
    """The u-free overlap ActiveSystem.build takes: o - shift, and with carried forces c and a
    linearised column of local compliance ``local`` also - (local - layer's) c (module docstring)."""
    offset = overlap_mm - shift
    if pushback_force_n is not None and local is not None:
        offset = offset - (local - layer.local_mm_per_n) * pushback_force_n
    return offset


def solve_thin_layer(
    directions: np.ndarray,
    layer: LayerCompliance,
    overlap_mm: np.ndarray,
    load: np.ndarray,
    *,
    ligament_rows: np.ndarray | None = None,
    ligament_law: LinearElements | None = None,
    fixed_dofs: tuple[str, ...] = (),
    shear: ShearTerms | None = None,
    length_scale_mm: float = 1.0,
    initial_active: np.ndarray | None = None,
    column: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
    pushback_force_n: np.ndarray | None = None,
    cycle_rtol: float = 1e-7,
    newton_rtol: float = 1e-10,
    max_iterations: int = 60,
) -> ThinLayerSolution:
    """Unilateral equilibrium of the rigid body on the coupled layer (module docstring).

    ``directions`` (n, 6): rows g_j of the layer's springs; ``overlap_mm`` (n,): d0, -inf where no
    opposing surface can be touched (the free layer around the contact);
    ``ligament_rows`` (n_l, 6) and ``ligament_law``: tension-only ligaments as in
    ``edem.mechanics.solve_unilateral``. ``initial_active`` (n,) bool: the first contact set
    (from the previous time point, so a slowly varying load needs one or two iterations; the
    programme is strictly convex, so the answer does not depend on it); by default the
    candidates that overlap (d0 >= 0), or every candidate where none does. ``column``: a
    nonlinear law's columns, f (n,) -> (excess (n,) mm, its derivative (n,) mm/N)
    (``ContactLaw.column_excess_mm``): w(f) = C f + excess(f), linearised at the
    previous iterate's forces (Newton; converged when the forces move by less than
    ``newton_rtol`` of the largest). ``pushback_force_n`` (n,): forces c (N) whose push-back
    C c adds to ``overlap_mm`` (the threshold law's stored forces in EDEM), solved for without
    forming it (module docstring, "Carried forces"); the deflection returned is then w - C c.
    Returns element forces for the springs then the ligaments, with ``active`` the contact set;
    raises SolverError like ``solve_unilateral``.
    """
    n_c = directions.shape[0]
    if ligament_rows is None:
        ligament_rows, ligament_law = np.zeros((0, 6)), LinearElements(np.zeros(0), np.zeros(0))
    free = np.ones(6, bool)
    for name in fixed_dofs:
        free[DOF_NAMES.index(name)] = False
    load = np.where(free, np.asarray(load, float), 0.0)
    to_newton = np.array([1.0, 1.0, 1.0] + [1.0 / length_scale_mm] * 3)
    free_block, dof_scale = np.ix_(free, free), 1.0 / to_newton[free]
    spring_scale = 1.0 / layer.local_mm_per_n  # N/mm: weighs the gap against the force in the NCP
    touchable = np.isfinite(overlap_mm)  # -inf: free layer with no opposing surface
    # A fixed DOF never moves: the contact set's system is formed over the free DOFs only.
    rows = np.ascontiguousarray(directions[:, free])
    warm = None if initial_active is None else initial_active & touchable
    # A cold start: the springs whose surfaces overlap before the layer deflects (d0 >= 0, every
    # candidate of a "carried" law), as ContactHistory.first_set starts a new candidate; on the
    # gap law's 3k-spring stance the first time point then took 5 iterations instead of 6 (8 for
    # the two-pole, 9 from every candidate). Without any, every candidate.
    overlapping = touchable & (overlap_mm >= 0.0)
    active = warm if warm is not None and np.any(warm) else overlapping if np.any(overlapping) else touchable.copy()
    ligament_active = ligament_law.offset_n > 0.0 if warm is not None else np.ones(ligament_rows.shape[0], bool)
    everything: np.ndarray | None = None
    seen: set[bytes] = set()
    force_scale = 1e-300
    # A nonlinear column, linearised at these forces: w(f) ~ (local + slope) f + nonlocal f + shift.
    linearised_at, local, shift = np.zeros(n_c), None, 0.0
    for iteration in range(1, max_iterations + 1):
        if column is not None:
            local, shift = _linearised(layer, column, linearised_at)
        offset = _offset(layer, overlap_mm, shift, local, pushback_force_n)
        system = ActiveSystem.build(layer, rows, offset, active, local, pushback_force_n)
        k_other, f_other = _others(ligament_rows, ligament_law, ligament_active, shear, active)
        stiffness = np.zeros((6, 6))
        stiffness[free_block] = system.stiffness() + k_other[free_block]
        rhs = load[free] - system.pushback() - f_other[free]
        u = np.zeros(6)
        # The 6 x 6's Cholesky factor both solves and says whether a free DOF is unrestrained.
        solved = _regular_solve(stiffness[free_block], dof_scale, rhs)
        regularised = False  # this iterate's set holds a free DOF only through the 1e-8 regularisation
        if solved is None and unrestrained_dofs(stiffness, free, length_scale_mm):
            if everything is None:
                full = ActiveSystem.build(layer, rows, offset, touchable, local, pushback_force_n)
                k_all, _ = _others(ligament_rows, ligament_law, np.ones_like(ligament_active), shear, touchable)
                everything = np.zeros((6, 6))
                everything[free_block] = full.stiffness() + k_all[free_block]
                missing = unrestrained_dofs(everything, free, length_scale_mm)
                if missing:
                    raise singular_stiffness_error(missing)
            if not np.any(active) and not np.any(ligament_active):
                raise SolverError("no equilibrium: no spring stays in compression under this load, so the load pulls the bodies apart")
            stiffness = stiffness + 1e-8 * everything  # a transiently small contact set
            regularised = True
        if solved is None:
            solved = np.linalg.solve(stiffness[free_block], rhs)
        u[free] = solved
        f = np.zeros(n_c)
        f[active] = system.forces(solved)
        w = system.deflection(layer, solved, f) + shift
        gap = w - overlap_mm - rows @ solved
        tension = ligament_law.offset_n + ligament_law.stiffness_n_per_mm * (ligament_rows @ u)
        new_active = np.where(active, f > 0.0, gap < 0.0)
        new_ligaments = tension > 0.0
        if not np.any(load) and not np.any(new_ligaments) and (regularised or not np.any(new_active)):
            # No load and no set that holds the free DOFs (none left, or one held only by the 1e-8
            # regularisation): the bodies are free, the only equilibrium carries no force, and the
            # pose is the reference one. Such sets are the last of overlaps of microns at rest
            # (springs resampled on M's chordal facets): on the cartilage ankle's 0.44 mm springs
            # one was left at 1e-7 N, which the balance check below refused (the pose it took had
            # slid 15 um along the dome's free ty); on 0.22 mm springs sets of 1 and 3 springs at
            # 1e-7 N alternated to the iteration limit.
            active, ligament_active, u = np.zeros(n_c, bool), new_ligaments, np.zeros(6)
            f, w = np.zeros(n_c), np.zeros(n_c)
            gap = -overlap_mm  # y = w - d0 - g u at u = 0
            tension = ligament_law.offset_n.copy()
            break
        settled = column is None or float(np.abs(f - linearised_at).max(initial=0.0)) <= newton_rtol * float(np.abs(f).max(initial=0.0))
        linearised_at = np.where(active, f, 0.0)
        if settled and np.array_equal(new_active, active) and np.array_equal(new_ligaments, ligament_active):
            break
        # Springs at zero force to round-off can flip for ever: accept a repeated set whose
        # violations (negative forces, penetrations) are below cycle_rtol of the force scale.
        # The scale is the largest met so far: unloading to zero, the last iterates carry forces
        # of round-off size only, and a scale taken from them would make round-off look large.
        signature = np.packbits(np.concatenate([new_active, new_ligaments])).tobytes()
        force_scale = max(force_scale, float(np.linalg.norm(load * to_newton)) + float(np.abs(f).sum()))
        violation = max(float(np.abs(np.minimum(f, 0.0)).sum()), float(np.abs(np.minimum(gap, 0.0) * spring_scale)[~active].sum()))
        if settled and signature in seen and violation <= cycle_rtol * force_scale:
            break
        seen.add(signature)
        if not np.any(new_active) and not np.any(new_ligaments):
            raise SolverError("no equilibrium: no spring stays in compression under this load, so the load pulls the bodies apart")
        active, ligament_active = new_active, new_ligaments
    else:
        raise SolverError(f"the thin-layer active-set iteration did not converge in {max_iterations} iterations")
    f = np.where(active, f, 0.0)
    ligament_force = np.where(ligament_active, tension, 0.0)
    resultant = directions.T @ f + ligament_rows.T @ ligament_force
    if shear is not None:
        resultant = resultant + shear.generalised_force(u, active)
    residual = np.where(free, resultant - load, 0.0)
    # The forces in play: the load, the solved forces and those the overlaps stand for (EDEM's
    # push-back: under a vanishing load the stored forces are what the solve balances away).
    pushed = float(np.sum((spring_scale * np.clip(overlap_mm, 0.0, None))[touchable]))
    if pushback_force_n is not None:
        pushed += float(np.abs(pushback_force_n).sum())  # stands for spring_scale C c without forming C c
    # (|f|: under a vanishing load the active set's forces are round-off of either sign, and their
    # signed sum cancelled the floor: 7e-17 N refused on the cartilage ankle at zero load)
    scale = float(np.linalg.norm(load * to_newton)) + float(np.abs(f).sum()) + pushed + 1e-9  # floor: a nanonewton, for a vanishing load
    # The 6 x 6 solve balances to round-off; only an accepted cycle or a regularised transient set
    # (1e-8 of the full stiffness) can leave more, and both stay far below 10 cycle_rtol.
    if float(np.linalg.norm(residual * to_newton)) > 10.0 * cycle_rtol * scale:
        raise SolverError(f"the thin-layer solve does not balance the load (residual {np.linalg.norm(residual):.3e} N)")
    outside = ~active
    return ThinLayerSolution(
        displacement=u,
        element_force_n=np.concatenate([f, tension]),
        active=np.concatenate([active, ligament_active]),
        iterations=iteration,
        force_residual_n=float(np.linalg.norm(residual[:3])),
        moment_residual_nmm=float(np.linalg.norm(residual[3:])),
        deflection_mm=w,
        gap_mm=np.where(active, 0.0, gap),
        max_penetration_mm=float(np.max(-gap[outside], initial=0.0)),
    )


def thin_layer_viscoelastic_increment(
    directions: np.ndarray,
    layer: LayerCompliance,
    overlap_mm: np.ndarray,
    ligament_rows: np.ndarray,
    ligament_law: LinearElements,
    shear: ShearTerms | None,
    elastic_active: np.ndarray,
    carried_force_n: np.ndarray,
    previous_load: np.ndarray,
    load: np.ndarray,
    weights: tuple[float, float],
    fixed_dofs: tuple[str, ...],
    column: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
    pushback: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Kelvin-Voigt increment on the coupled layer (``edem.viscoelastic``, eq. 6.18).

    The contact set is frozen at the quasi-static set under T_k (``elastic_active``: springs then
    ligaments) plus the springs that carried a force into the step (so they can creep back); u = K^-1 [phi (T_{k-1} - p) + psi (T_k - T_{k-1})]
    with K the coupled contact stiffness and p the push-back of that set at u = 0. A nonlinear
    ``column`` (``solve_thin_layer``) is linearised at the forces carried into the step, the
    state at u = 0, as the spring bed linearises its law there. ``pushback``: the carried forces'
    push-back C f_carried adds to ``overlap_mm`` (``solve_thin_layer``'s ``pushback_force_n``;
    as they are all in the set, their column needs no solve). Returns u and the elastic element
    forces (springs then ligaments) to commit.
    """
    phi, psi = weights
    n_c = directions.shape[0]
    active = elastic_active[:n_c] | (carried_force_n > 0.0)
    ligament_active = elastic_active[n_c:] | (ligament_law.offset_n > 0.0)
    free = np.array([d not in fixed_dofs for d in DOF_NAMES])
    u = np.zeros(6)
    f = np.zeros(n_c)
    if np.any(active):
        local, shift = (None, 0.0) if column is None else _linearised(layer, column, carried_force_n)
        pushed = carried_force_n if pushback else None
        offset = _offset(layer, overlap_mm, shift, local, pushed)
        rows = np.ascontiguousarray(directions[:, free])  # the free DOFs' (solve_thin_layer)
        system = ActiveSystem.build(layer, rows, offset, active, local, pushed)
        k_other, f_other = _others(ligament_rows, ligament_law, ligament_active, shear, active)
        if phi or psi:
            k = system.stiffness() + k_other[np.ix_(free, free)]
            rhs = phi * (previous_load[free] - system.pushback() - f_other[free]) + psi * (load - previous_load)[free]
            u[free] = np.linalg.lstsq(k, rhs, rcond=None)[0]
        f[active] = np.maximum(system.forces(u[free]), 0.0)
    tension = ligament_law.offset_n + ligament_law.stiffness_n_per_mm * (ligament_rows @ u)
    return u, np.concatenate([f, np.where(ligament_active, np.maximum(tension, 0.0), 0.0)])


def coupled_layer_mesh(scene) -> SurfaceMesh:
    """The intrinsic surface of the scene's springs (one per non-degenerate mobile triangle)."""
    return SurfaceMesh.from_surface(scene.mobile.vertices_mm, scene.mobile.triangles[scene.spring_triangle])


def overlap_and_deflection_mm(scene, geometry, force_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the layer must deflect and what it does deflect under given forces, at every one of M's springs.

    ``geometry``: M's springs at a pose (:func:`edem.springs.spring_geometry`); ``force_n`` (n,)
    N: a normal force on each spring (a pressure times the spring's area). Returns the overlap
    d = t - h (n,) mm of the undeformed articular surfaces along each spring (-inf where the ray
    meets no F), and the coupled layer's deflection w = C f (n,) mm, C built over the whole
    spring-bearing surface with the scene's symbol, stack and thickness as :meth:`CoupledStep.build`
    builds it. Where the bodies touch, w = d: so a reference's contact pressure put through C and
    set against d at the reference's pose measures the bed's compliance against the reference's
    (``verification.bed_compliance``). Only for the gap laws (``thin_layer = "overlap"``) on the
    coupled layer: InputError (key ``cartilage.law`` or ``cartilage.coupling``) otherwise.
    """
    cartilage = scene.cartilage
    if cartilage.spring_law.thin_layer != "overlap":
        raise InputError(f"the {cartilage.law} law has no overlap t - h for the layer to deflect", key="cartilage.law", expected='a gap law ("gap")')
    if cartilage.coupling != "thin-layer":
        raise InputError(f'the "{cartilage.coupling}" bed has no layer operator', key="cartilage.coupling", expected='the coupled layer ("thin-layer")')
    n = geometry.spring_length_mm.shape[0]
    thickness = geometry.thickness_mm if geometry.thickness_mm is not None else np.full(n, float(cartilage.thickness_mm))
    mesh, domain = coupled_layer_mesh(scene), np.arange(n)
    stack = sandwich_thickness_mm(thickness, geometry, cartilage, domain)
    layer = layer_compliance(mesh, domain, stack, cartilage.youngs_modulus_mpa, cartilage.poissons_ratio, False, cartilage.layer_symbol)
    return thickness - geometry.spring_length_mm, layer.deflection(np.asarray(force_n, float))


def coupled_domain(mesh: SurfaceMesh, candidates: np.ndarray, band_mm: float) -> np.ndarray:
    """The springs the coupled layer covers (sorted indices): the candidates and a band ``band_mm`` wide.

    Where that band covers at least half the spring-bearing surface, the whole surface instead:
    the layer is then the cartilage up to its free edge, and its operator pattern and band
    ordering are built once per run rather than once per time point (the band moves with the
    candidates). On the ankles, whose band covers about 80 % of the surface, that outweighed the
    larger factorisation (benchmarks/bench_thin_layer.py).
    """
    n = mesh.triangles.shape[0]
    band = mesh.neighbourhood(candidates, band_mm, enough=(n + 1) // 2)
    return np.arange(n) if 2 * np.count_nonzero(band) >= n else np.flatnonzero(band)


def sandwich_thickness_mm(thickness_mm: np.ndarray, geometry, cartilage, domain: np.ndarray) -> np.ndarray:
    """The layer's local thickness (n_d,) mm over the springs ``domain`` as ``layer_compliance``
    takes it: split into M's and F's layers (2, n_d) where the scene gives both sides a layer and
    the bed's ``thin_layer_stack`` is "sandwich" (each layer bonded to its bone, frictionless
    between them: docs/method.md); else as it is (one layer: the lumped pair, or a side without
    cartilage). The split is M's share t_M / T of the springs' total thickness T = t_M + t_F
    (``edem.thickness``: t_F at F's triangle each ray meets), which is the law's thickness t_M,
    t_F for the gap laws and the bone-to-bone length's shares for the threshold law."""
    layers = cartilage.layers
    if layers is None or geometry.thickness_mm is None or cartilage.bed_keys.thin_layer_stack != "sandwich":
        return thickness_mm
    total = geometry.thickness_mm[domain]
    mobile = layers.mobile.thickness_mm[domain]
    sides = [side for side in (mobile, total - mobile) if np.any(side > 0.0)]
    if len(sides) == 1:  # one side without cartilage: one layer, the lumped bed's to the bit
        return thickness_mm
    # t_i (h / T): exactly t_M and t_F where h is T (the gap laws), so M's layer, bonded to the
    # moving body, keeps its thickness's bits from one time point to the next (its terms are kept)
    ratio = thickness_mm / total
    return np.stack([side * ratio for side in sides])


class ContactHistory:
    """The forces and gaps of M's springs at the last two time points solved, whose extrapolation
    is the next solve's first contact set.

    Over a stance the contact grows, shrinks and moves by tens of springs a time point, and
    starting from the last contact set the active set took two or three more iterations to reach
    it (the first finding the springs that enter, the next the few that the entering ones lift
    or press). Each spring's force and gap vary smoothly from one time point to the next, so
    their linear extrapolation, f_k + (f_k - f_k-1) for a spring in contact at k and
    y_k + (y_k - y_k-1) out of contact, predicts the next set: on the idealised ankle's stances
    within 0-2 springs of the answer at most time points (docs/method.md). A spring that was not
    a candidate at k - 1 keeps its state at k; one that was not a candidate at k starts in contact
    where the surfaces overlap before the layer deflects (d0 >= 0: the threshold law's candidates,
    whose window the contact fills; on the gap laws, new candidates lie at the window's far edge,
    out of contact)."""

    def __init__(self, n_springs: int) -> None:
        self.force_n = np.zeros((2, n_springs))  # at k - 1, k
        self.gap_mm = np.full((2, n_springs), np.nan)  # NaN: not a candidate then
        self.in_contact = np.zeros(n_springs, bool)  # at k
        self.recorded = 0

    def record(self, candidate_index: np.ndarray, solution: ThinLayerSolution) -> None:
        """The solution of a time point (candidates in ``candidate_index`` order, then ligaments)."""
        n_c = candidate_index.shape[0]
        self.force_n[0], self.gap_mm[0] = self.force_n[1], self.gap_mm[1]
        self.force_n[1] = 0.0
        self.gap_mm[1] = np.nan
        self.in_contact[:] = False
        active = solution.active[:n_c]
        self.force_n[1, candidate_index] = np.where(active, solution.element_force_n[:n_c], 0.0)
        self.gap_mm[1, candidate_index] = solution.gap_mm
        self.in_contact[candidate_index] = active
        self.recorded += 1

    def first_set(self, springs: np.ndarray, overlap_mm: np.ndarray) -> np.ndarray | None:
        """(n_d,) bool over the layer's springs ``springs`` (sorted indices into M's), whose overlaps
        d0 (n_d,) mm are ``overlap_mm``; None before any record."""
        if not self.recorded:
            return None
        if springs.shape[0] == self.in_contact.shape[0]:  # every spring, in order (the layer over the whole surface): no gathers
            force, gap, contact = self.force_n, self.gap_mm, self.in_contact
        else:
            force, gap, contact = self.force_n[:, springs], self.gap_mm[:, springs], self.in_contact[springs]
        before = np.isfinite(gap[0]) if self.recorded > 1 else np.zeros(springs.shape[0], bool)
        force_next = np.where(before, 2.0 * force[1] - force[0], force[1])
        gap_next = np.where(before, 2.0 * gap[1] - gap[0], gap[1])
        new = np.isnan(gap[1])  # not a candidate at k
        return np.where(contact, force_next > 0.0, np.where(new, overlap_mm >= 0.0, gap_next < 0.0))


@dataclass(frozen=True)
class CoupledStep:
    """One time point of DEM/EDEM on the coupled layer: the layer, overlap and elements.

    Where the law's layer is bonded to all of M (``thin_layer_extent = "surface"``, the gap
    laws), it covers the candidate springs and a band of the surface around them 3 sqrt(b) h
    wide (three decay lengths of the bulge; there the layer is free: f = 0, no opposing surface),
    so the layer can bulge outside the contact; beyond it the boundary is natural. Where that
    band would cover half the surface, the layer is the whole surface (``coupled_domain``); b is the
    symbol's largest screening.
    Where the cartilage only fills the gap (``"candidates"``, the threshold law, whose FE twin is
    the slab), the layer is the candidates, and it ends at their boundary with a free lateral
    face (the smoothed field vanishes there, as at the surface's free edge). Local
    thickness: the length the law's shear springs use (t for the gap law, the current spring
    length for the threshold law; on the band t or the candidates' median), split into the two
    layers of a sandwich where both sides have one (``sandwich_thickness_mm``). The overlap d0 is t - h for an
    "overlap" law (gap) or C f_carried for a "carried" law (threshold: the EDEM push-back of the
    forces committed at the previous step, zero in DEM); -inf on the band. The push-back is kept
    as its forces (``pushback_force_n``, with ``overlap_mm`` 0) and solved for by the contact
    solve's own factorisation (module docstring, "Carried forces").
    """

    layer: LayerCompliance
    overlap_mm: np.ndarray  # (n_d,) over the layer's springs
    directions: np.ndarray  # (n_d, 6)
    candidate: np.ndarray  # (n_d,) bool: the layer's springs that are candidates, in candidate order
    springs: np.ndarray  # (n_d,) int: the layer's springs among all of M's
    ligament_rows: np.ndarray
    ligament_law: LinearElements
    column: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None  # a nonlinear law's columns (solve_thin_layer)
    pushback_force_n: np.ndarray | None = None  # (n_d,) a "carried" law's forces c, whose push-back C c adds to overlap_mm
    layer_thickness_mm: np.ndarray | None = None  # (n_d,) or (L, n_d) each layer's local thickness (layer_compliance's)
    shortest_screening: float | None = None  # b of the symbol's shortest term (None: no term)

    @functools.cached_property
    def shortest_smoothing_mm(self) -> float:
        """sqrt(b) h of the symbol's shortest term at the candidates' median thickness of the
        thinnest layer (a sandwich's terms are as short as their own layer is thin); inf: no term.
        Formed only for the resolution warning."""
        if self.shortest_screening is None:
            return np.inf
        layers = np.reshape(self.layer_thickness_mm, (-1, self.candidate.shape[0]))[:, self.candidate]
        thinnest = min((float(np.median(h[h > 0.0])) for h in layers if np.any(h > 0.0)), default=np.inf)
        return float(np.sqrt(self.shortest_screening) * thinnest)

    @staticmethod
    def build(mesh: SurfaceMesh, geometry, cartilage, carried_force_n: np.ndarray, directions: np.ndarray, ligament_rows, ligament_law,
              history_force_n: np.ndarray | None = None, gap_mm: np.ndarray | None = None) -> "CoupledStep":
        """``directions`` (n_c, 6) and ``carried_force_n`` (n_c,) are those of the candidates.

        A creeping Kelvin-Voigt step (:class:`edem.viscoelastic.Creep`; ``cartilage`` then c0 times
        stiffer): ``history_force_n`` (n_springs,), forces over all of M's springs whose push-back
        joins the carried forces' (-S_n), and ``gap_mm`` (n_springs,), a carried law's gaps at the
        step's start (its overlap is then -gap instead of 0)."""
        cand = np.flatnonzero(geometry.candidate)
        law = cartilage.spring_law
        candidate_thickness = law.shear_length_mm(geometry.spring_length_mm[cand], geometry.candidate_thickness_mm(cartilage))  # the h of k_s = G / h
        screenings = cartilage.layer_symbol.screenings
        b = max(screenings, default=0.0)
        ends = law.thin_layer_extent == "candidates"
        if ends or b == 0.0:  # the layer is the candidates
            domain, thickness = cand, candidate_thickness
        else:
            # The band: t, or for a law whose thickness is the spring length, the candidates' median;
            # with measured thickness (edem.thickness) each spring of the band has its own t.
            measured = geometry.thickness_mm is not None and law.needs_thickness
            band_thickness = float(cartilage.thickness_mm) if law.needs_thickness and not measured else float(np.median(candidate_thickness)) if cand.size else 1.0
            domain = coupled_domain(mesh, cand, 3.0 * np.sqrt(b) * band_thickness)
            thickness = geometry.thickness_mm[domain] if measured else np.full(domain.shape, band_thickness)
            thickness[geometry.candidate[domain]] = candidate_thickness  # domain is sorted: candidates in their order
        is_candidate = geometry.candidate[domain]
        length = geometry.spring_length_mm[domain]
        # The coarse smoothing space pays where it is built once per run: on the layer over the
        # whole surface. A layer on the candidates (or a band around them) is a new cell set at
        # every time point, where building it cost more than it saved (the threshold law's EDEM
        # stance, 29k springs: 14.5x the springs against 6.3x fine, benchmarks/bench_coarse_smoothing.py),
        # so such a layer stays on the springs' vertices.
        whole = domain.shape[0] == mesh.triangles.shape[0]
        resolution = cartilage.bed_keys.thin_layer_smoothing_resolution if whole else 0.0
        stack = sandwich_thickness_mm(thickness, geometry, cartilage, domain)
        layer = layer_compliance(mesh, domain, stack, cartilage.youngs_modulus_mpa, cartilage.poissons_ratio, ends, cartilage.layer_symbol,
                                 resolution)
        overlap = np.full(domain.shape, -np.inf)
        pushback = None
        if law.thin_layer == "carried":
            overlap[is_candidate] = 0.0 if gap_mm is None else -gap_mm[domain[is_candidate]]
            if np.any(carried_force_n):
                pushback = np.zeros(domain.shape)
                pushback[is_candidate] = carried_force_n
        else:
            overlap[is_candidate] = (thickness - length)[is_candidate]
        if history_force_n is not None:
            pushback = history_force_n[domain] if pushback is None else pushback + history_force_n[domain]
        rows = np.zeros((domain.shape[0], 6))
        rows[is_candidate] = directions  # domain is sorted, so candidates keep their order
        column = None
        if law.nonlinear:
            column = functools.partial(law.column_excess_mm, area_mm2=mesh.area_mm2[domain], confined_modulus_mpa=cartilage.confined_modulus_mpa,
                                       thickness_mm=thickness)
        return CoupledStep(layer, overlap, rows, is_candidate, domain, ligament_rows, ligament_law, column, pushback, stack,
                           min(screenings, default=None))

    def resolution_warning(self, mesh: SurfaceMesh) -> list[str]:
        """A warning when the symbol's shortest smoothing length is below the springs' size (the
        side sqrt(2 A) of a median triangle): that term is then not resolved at the contact edge.
        Two-pole, 2 mm layer, nu 0.49 (length 0.46 mm): pressure-field L2 error against the FE
        11 / 7.6 / 7.1 / 6.2 % at springs 0.86 / 0.65 / 0.56 / 0.46 mm across (the edge zigzags at
        0.86 mm); the Pade's, whose term is about h long, 6.6-6.8 % (docs/method.md, section 3)."""
        spacing = float(np.sqrt(2.0 * np.median(mesh.area_mm2[self.springs])))
        if self.shortest_smoothing_mm >= spacing:
            return []
        return [f"the thin-layer symbol's shortest smoothing length, {self.shortest_smoothing_mm:.2g} mm, is below the springs' size "
                f"{spacing:.2g} mm: that term is under-resolved at the contact edge (pressures there may zigzag between neighbouring "
                f"springs); springs about {self.shortest_smoothing_mm:.2g} mm across resolve it (a finer mesh)"]

    def _to_candidates(self, solution: ThinLayerSolution) -> ThinLayerSolution:
        n_d, c = self.directions.shape[0], self.candidate
        keep = np.concatenate([c, np.ones(solution.element_force_n.shape[0] - n_d, bool)])
        solution.element_force_n = solution.element_force_n[keep]
        solution.active = solution.active[keep]
        solution.deflection_mm, solution.gap_mm = solution.deflection_mm[c], solution.gap_mm[c]
        return solution

    def solve(self, load, fixed_dofs, shear, length_scale_mm, history: "ContactHistory | None" = None,
              first: np.ndarray | None = None) -> ThinLayerSolution:
        """The coupled solve; forces, contact set, deflection and gap of the candidates (then ligaments).

        ``first`` (n_c,) bool over the candidates: the active set's first iterate; else
        ``history``: the previous time points' solutions, whose extrapolation is the first iterate
        (``ContactHistory.first_set``); None: a cold start (``solve_thin_layer``'s default). The
        programme's answer does not depend on the first iterate."""
        if first is not None:
            initial = np.zeros(self.candidate.shape[0], bool)
            initial[self.candidate] = first
        else:
            initial = None if history is None else history.first_set(self.springs, self.overlap_mm)
        return self._to_candidates(
            solve_thin_layer(
                self.directions, self.layer, self.overlap_mm, load, ligament_rows=self.ligament_rows, ligament_law=self.ligament_law,
                fixed_dofs=fixed_dofs, shear=self._shear(shear), length_scale_mm=length_scale_mm,
                initial_active=initial, column=self.column,
                pushback_force_n=self.pushback_force_n,
            )
        )

    def force_free(self, direction: np.ndarray | None) -> ThinLayerSolution | None:
        """The unloaded time point of a creeping step (``edem.beds.Bed.force_free``): with no force
        anywhere the layer keeps the deflection of its carried forces, so a candidate's gap at u is
        -d0 - g . u with d0 = o + C c (module docstring, "Carried forces")."""
        carried = np.zeros(int(self.candidate.sum()))  # C c at the candidates
        if self.pushback_force_n is not None:
            carried = self.layer.deflection(self.pushback_force_n)[self.candidate]
        overlap = self.overlap_mm[self.candidate] + carried
        rows = self.directions[self.candidate]
        u = touch_motion(-overlap, rows, self.ligament_rows, self.ligament_law, direction)
        if u is None:
            return None
        gap = -overlap - rows @ u
        tension = self.ligament_law.offset_n + self.ligament_law.stiffness_n_per_mm * (self.ligament_rows @ u)
        n_c = rows.shape[0]
        return ThinLayerSolution(
            displacement=u, element_force_n=np.concatenate([np.zeros(n_c), tension]), active=np.zeros(n_c + tension.shape[0], bool),
            iterations=0, force_residual_n=0.0, moment_residual_nmm=0.0, deflection_mm=-carried,  # w - C c with f = 0
            gap_mm=gap, max_penetration_mm=0.0,
        )

    def _shear(self, shear: ShearTerms | None) -> ShearTerms | None:
        """The candidates' shear springs spread over the layer's springs (zero on the band)."""
        if shear is None:
            return None
        c = self.candidate

        def spread(values):
            out = np.zeros((c.shape[0],) + values.shape[1:])
            out[c] = values
            return out

        return ShearTerms(spread(shear.arm_mm), spread(shear.normals), spread(shear.stiffness_n_per_mm), spread(shear.stored_force_n))

    def viscoelastic_increment(self, elastic, carried_force_n, previous_load, load, weights, shear, fixed_dofs):
        """Kelvin-Voigt increment (``thin_layer_viscoelastic_increment``) in candidate order."""
        c = self.candidate
        n_c = int(c.sum())
        active, carried = np.zeros(c.shape[0], bool), np.zeros(c.shape[0])
        active[c], carried[c] = elastic.active[:n_c], carried_force_n
        u, force = thin_layer_viscoelastic_increment(
            self.directions, self.layer, self.overlap_mm, self.ligament_rows, self.ligament_law, self._shear(shear),
            np.concatenate([active, elastic.active[n_c:]]), carried, previous_load, load, weights, fixed_dofs, self.column,
            pushback=self.pushback_force_n is not None,
        )
        return u, np.concatenate([force[: c.shape[0]][c], force[c.shape[0]:]])
