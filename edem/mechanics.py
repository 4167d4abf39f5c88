"""Rigid-body mechanics of the spring bed: operators, stiffness and the unilateral solve.

Notation of docs/method.md#1-two-rigid-bones-and-a-bed-of-springs and thesis chapter 3. The mobile body M has the generalised displacement
u = (u_G, q) in R^6 about its reference point G. A point c of M moves by B u = u_G + q x (c - G)
(eq. 3.1-3.3). Every load-carrying element j (a contact spring or a ligament) is reduced to

    a unit generalised direction g_j in R^6, with the element's approach delta_j = g_j . u, and
    a scalar force s_j(delta_j) (compression for springs, tension for ligaments),

so that the element resists the motion with the generalised force max(s_j, 0) g_j. For a contact
spring g = B^T n = (n, (c - G) x n); for a ligament pulling M towards F along e, g = -B^T e.
Contact springs may also carry shear: f_t = f_t0 + A k_s (I - n n^T) B u while in contact.

Static equilibrium (eq. 3.13, 3.18 with the push-back folded into s_j and f_t0) is the
stationarity of the convex energy Pi(u) = sum_j phi_j(g_j . u) + shear - T . u with
phi_j' = max(s_j, 0). ``solve_unilateral`` minimises it by a semismooth Newton method (a
primal-dual active set that adds and removes elements), globalised by an Armijo line search,
and ends with the KKT check of docs/method.md#1-two-rigid-bones-and-a-bed-of-springs.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs

from geometries.errors import SolverError
from edem.laws import ElementLaw, LinearElements
from geometries.rowwise import rows_times
from geometries.triangle_kernels import cross_rows

DOF_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")


def confined_modulus_mpa(youngs_modulus_mpa: float, poissons_ratio: float) -> float:
    """E' = E (1 - nu) / ((1 + nu)(1 - 2 nu)): the normal spring modulus of eq. 3.7."""
    nu = poissons_ratio
    return youngs_modulus_mpa * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))


def skew(v: np.ndarray) -> np.ndarray:
    """W_v with W_v a = v x a (eq. 3.2)."""
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_matrix(rotation_vector_rad: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: the finite rotation (3, 3) whose axis-angle vector (3,) is
    ``rotation_vector_rad``, R = cos a I + sin a W_k + (1 - cos a) k k^T for the unit axis k.

    Formed from Python floats: it is called a few times per time point, where numpy's per-call
    overhead on 3-vectors costs several times the arithmetic.
    """
    x, y, z = np.asarray(rotation_vector_rad, float).tolist()
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-300:
        return np.eye(3)
    if not math.isfinite(angle):  # (math.sin raises on inf: nan, as numpy's sine gives, for callers to refuse)
        return np.full((3, 3), np.nan)
    x, y, z = x / angle, y / angle, z / angle
    sin, cos = math.sin(angle), math.cos(angle)
    versine = 1.0 - cos
    return np.array(
        [
            [cos + versine * x * x, versine * x * y - sin * z, versine * x * z + sin * y],
            [versine * x * y + sin * z, cos + versine * y * y, versine * y * z - sin * x],
            [versine * x * z - sin * y, versine * y * z + sin * x, cos + versine * z * z],
        ]
    )


def rotation_vector(rotation: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_matrix` (axis-angle vector of a rotation matrix, angle < pi);
    in Python floats, as :func:`rotation_matrix` (once per time point)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(rotation, float).tolist()
    angle = math.acos(min(max((r00 + r11 + r22 - 1.0) / 2.0, -1.0), 1.0))
    factor = 0.5 if angle < 1e-8 else angle / (2.0 * math.sin(angle))
    return np.array([factor * (r21 - r12), factor * (r02 - r20), factor * (r10 - r01)])


def generalised_directions(points_mm: np.ndarray, directions: np.ndarray, reference_point_mm: np.ndarray) -> np.ndarray:
    """Rows B_i^T d_i = (d_i, (c_i - G) x d_i): the rigid motion seen along d_i at c_i (eq. 3.3)."""
    out = np.empty((points_mm.shape[0], 6))
    out[:, :3] = directions
    out[:, 3:] = cross_rows(points_mm - reference_point_mm, directions)
    return out


def turn_rows(rows: np.ndarray, rotation: np.ndarray, extra: int = 0) -> np.ndarray:
    """Rows (d, (c - G) x d) of a body's points and directions after the body turned by
    ``rotation`` about G: both parts turn with it, (R d, R ((c - G) x d)), so rows measured once
    at the reference pose give the rows at any pose by one (n, 6) x (6, 6) product. ``extra``
    rows are left for the caller to fill (e.g. the ligaments', appended without a copy)."""
    out = np.empty((rows.shape[0] + extra, 6))
    turn = np.zeros((6, 6))
    turn[:3, :3] = turn[3:, 3:] = rotation.T
    rows_times(rows, turn, out=out[: rows.shape[0]])
    return out


@dataclass(frozen=True)
class ShearTerms:
    """Shear of the contact springs, active only while the spring is in compression (eq. 3.6)."""

    arm_mm: np.ndarray  # (n, 3) c_i - G
    normals: np.ndarray  # (n, 3)
    stiffness_n_per_mm: np.ndarray  # (n,) A_i k_s
    stored_force_n: np.ndarray  # (n, 3) tangential stored force (EDEM push-back)

    def stiffness(self, active: np.ndarray) -> np.ndarray:
        """sum over active springs of A k_s B^T (I - n n^T) B = A k_s (B^T B - g g^T)."""
        w = self.stiffness_n_per_mm * active
        if not np.any(w):
            return np.zeros((6, 6))
        r = self.arm_mm
        wr = (w[:, None] * r).sum(axis=0)
        k = np.zeros((6, 6))
        k[:3, :3] = w.sum() * np.eye(3)
        k[:3, 3:] = -skew(wr)
        k[3:, :3] = skew(wr)
        k[3:, 3:] = (w * np.einsum("ij,ij->i", r, r)).sum() * np.eye(3) - np.einsum("i,ij,ik->jk", w, r, r)
        g = generalised_directions(r, self.normals, np.zeros(3))
        return k - np.einsum("i,ij,ik->jk", w, g, g)

    def force(self, u: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Tangential spring forces (n, 3): stored part plus A k_s (I - n n^T) B u, zero if inactive."""
        displacement = u[:3] + cross_rows(u[3:], self.arm_mm)
        tangential = displacement - np.einsum("ij,ij->i", displacement, self.normals)[:, None] * self.normals
        f = self.stored_force_n + self.stiffness_n_per_mm[:, None] * tangential
        return f * active[:, None]

    def generalised_force(self, u: np.ndarray, active: np.ndarray) -> np.ndarray:
        f = self.force(u, active)
        return np.concatenate([f.sum(axis=0), cross_rows(self.arm_mm, f).sum(axis=0)])


@dataclass
class UnilateralSolution:
    """Outcome of one static solve (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs): displacement, element forces and the KKT figures."""

    displacement: np.ndarray  # (6,) u = (u_G mm, q rad)
    element_force_n: np.ndarray  # (m,) s_j(u); the element carries max(s_j, 0)
    active: np.ndarray  # (m,) bool, s_j > 0
    iterations: int
    force_residual_n: float  # |sum of element forces - applied force| over the free DOFs
    moment_residual_nmm: float


def _free_mask(fixed_dofs: tuple[str, ...]) -> np.ndarray:
    free = np.ones(6, bool)
    for name in fixed_dofs:
        free[DOF_NAMES.index(name)] = False
    return free


@functools.lru_cache(maxsize=16)
def _dof_frame(fixed_dofs: tuple[str, ...], length_scale_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(free (6,) bool, free DOF indices (p,), to_newton (6,), to_newton (p,), dof_scale (p,)) of a
    solve, read-only: the same for every time point of a run, so built once (a handful of small
    arrays, whose construction costs more than a solve's arithmetic at a few thousand springs)."""
    free = _free_mask(fixed_dofs)
    dofs = np.flatnonzero(free)
    to_newton = np.array([1.0, 1.0, 1.0] + [1.0 / length_scale_mm] * 3)  # moments in N
    dof_scale = np.array([1.0, 1.0, 1.0] + [length_scale_mm] * 3)[dofs]
    frame = (free, dofs, to_newton, to_newton[dofs], dof_scale)
    for array in frame:
        array.flags.writeable = False
    return frame


def singular_stiffness_error(missing: list[str]) -> SolverError:
    """The refusal for DOFs that no element resists, with the ways to restrain them."""
    return SolverError(
        f"the stiffness matrix is singular: nothing resists motion along {', '.join(missing)}; "
        "fix these DOFs in [constraints] fixed_dofs, or give the cartilage shear stiffness "
        "(cartilage.shear_modulus_mpa) or ligaments"
    )


def _norm(v: np.ndarray) -> float:
    """Euclidean norm of a short vector (np.linalg.norm's overhead dominates at this size)."""
    return math.sqrt(float(v @ v))


def _regular_solve(stiffness: np.ndarray, scale: np.ndarray, rhs: np.ndarray, rtol: float = 1e-10) -> np.ndarray | None:
    """x with stiffness @ x = rhs if the stiffness is regular, else None.

    ``stiffness`` (p, p) with p <= 6 free DOFs (N/mm, N, N mm), ``scale`` (p,) and ``rhs`` (p,).
    Regular: positive definite with every Cholesky pivot well above round-off (``1e3 rtol`` of
    its largest entry once the DOFs are in the same units: ``scale`` is 1 for a translation, a
    characteristic length for a rotation); then no DOF is unrestrained at ``rtol`` and
    :func:`unrestrained_dofs` needs no eigensolve. The factor that decides it also gives x.
    LAPACK's potrf/potrs are called directly: at 6 x 6 the checks and dispatch of
    numpy.linalg or scipy.linalg.cho_factor cost several times the factorisation itself.
    """
    if not scale.size:  # nothing free, nothing to restrain
        return np.zeros(0)
    a = stiffness / (scale[:, None] * scale)
    factor, info = dpotrf(a, lower=1, clean=0)
    if info:  # a leading minor not positive definite
        return None
    pivots = factor.diagonal()  # sqrt of the pivots a_jj - sum_m L_jm^2
    if not (pivots * pivots).min() > 1e3 * rtol * np.abs(a).max():  # (a nan pivot fails it too)
        return None
    x, _ = dpotrs(factor, rhs / scale, lower=1)
    return x / scale


def unrestrained_dofs(stiffness: np.ndarray, free: np.ndarray, length_scale_mm: float, rtol: float = 1e-10) -> list[str]:
    """Names of the free DOFs along which the 6x6 stiffness vanishes (the null space of K_free).

    Rotations are scaled by a characteristic length so that all blocks are in N/mm before the
    eigenvalues are compared (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs: detect rank deficiency, say which DOFs are unrestrained).
    """
    scale = np.array([1.0, 1.0, 1.0, length_scale_mm, length_scale_mm, length_scale_mm])[free]
    if _regular_solve(stiffness[np.ix_(free, free)], scale, np.zeros(scale.size), rtol) is not None:
        return []  # the common case: no eigensolve
    k = stiffness[np.ix_(free, free)] / np.outer(scale, scale)
    values, vectors = np.linalg.eigh(k)
    top = float(np.abs(values).max(initial=0.0))
    null = vectors[:, values <= rtol * top] if top > 0 else np.eye(k.shape[0])
    if null.size == 0:
        return []
    weight = np.sqrt((null**2).sum(axis=1))
    return [str(n) for n in np.array(DOF_NAMES)[free][weight > 0.3]]


def assemble_stiffness(directions: np.ndarray, stiffness_n_per_mm: np.ndarray, active: np.ndarray, shear: ShearTerms | None = None) -> np.ndarray:
    """K = sum over active elements of c_j g_j g_j^T plus their shear: the 6x6 of eq. 3.12."""
    k = directions.T @ (directions * (stiffness_n_per_mm * active)[:, None])
    if shear is not None:
        k = k + shear.stiffness(active[: shear.normals.shape[0]])
    return k


#: rows of a sample that :func:`balanceable` tries before all of them
_BALANCE_SAMPLE = 256


def balanceable(directions: np.ndarray, load: np.ndarray, free: np.ndarray, to_newton: np.ndarray) -> bool:
    """Whether T = sum_j lambda_j g_j has a solution with every lambda_j >= 0 (non-negative least squares)."""
    from scipy.optimize import nnls

    a = (directions * to_newton)[:, free].T
    b = (load * to_newton)[free]
    tolerance = 1e-6 * max(float(np.linalg.norm(b)), 1e-300)
    # Fewer rows span a smaller cone, so a sample that balances the load says yes for all of them
    # (the misfit can only fall as rows are added) at a fraction of the cost; else all the rows.
    step = a.shape[1] // _BALANCE_SAMPLE
    if step > 1 and nnls(np.ascontiguousarray(a[:, ::step]), b)[1] <= tolerance:
        return True
    return nnls(a, b)[1] <= tolerance


def solve_unilateral(
    directions: np.ndarray,
    law: ElementLaw,
    load: np.ndarray,
    *,
    fixed_dofs: tuple[str, ...] = (),
    shear: ShearTerms | None = None,
    length_scale_mm: float = 1.0,
    rtol: float = 1e-10,
    cycle_rtol: float = 1e-7,
    max_iterations: int = 60,
    start_displacement: np.ndarray | None = None,
) -> UnilateralSolution:
    """Equilibrium sum_j max(s_j(g_j . u), 0) g_j + shear(u) = T of the unilateral elements.

    ``directions`` (m, 6) are the rows g_j and ``law`` (:mod:`edem.laws`) gives s_j. ``shear`` applies to the first
    ``len(shear.normals)`` elements (the contact springs; ligaments carry no shear). This is the
    minimisation of the convex energy Pi by a semismooth Newton iteration: each step solves with
    the stiffness of the current active set, which adds elements as well as removes them (the
    thesis's removal-only loop can stop on a wrong set), damped by an Armijo line search on Pi and
    a fraction-to-boundary rule for log-law elements. The first step starts from u = 0 and takes
    every element as active, as DEM does; given ``start_displacement`` (6,) (e.g. the previous
    time point's solution) it starts there instead, with the elements compressed there as the
    active set, unless they leave a free DOF unrestrained or a log element is crushed there.
    Pi is convex with one minimiser, so the start changes the iterations, not the answer (up to
    the tolerances below). On return the KKT conditions hold: active elements are compressed,
    inactive ones are not, and the residual of force and moment balance is at round-off (or below
    ``cycle_rtol`` of the force scale when a spring at zero force makes the active set cycle).

    Raises SolverError when no equilibrium exists (the load pulls the bodies apart) or a free DOF
    is unrestrained (singular stiffness), naming the DOFs.
    """
    m = directions.shape[0]
    free, dofs, to_newton, to_newton_f, dof_scale = _dof_frame(tuple(fixed_dofs), float(length_scale_mm))
    load = np.where(free, np.asarray(load, float), 0.0)
    n_shear = 0 if shear is None else shear.normals.shape[0]
    # The iteration runs on the free DOFs only (u is zero on the fixed ones): the rows g_j
    # restricted to them, stored as p <= 6 contiguous columns (p, m), so every product over the
    # elements is p / 6 of the full one and runs along contiguous columns. The products are
    # einsums, not BLAS calls, which OpenBLAS would spread over threads (see geometries.rowwise).
    cols = np.ascontiguousarray(directions[:, dofs].T)
    load_f = load[dofs]

    def full(u_f: np.ndarray) -> np.ndarray:
        u = np.zeros(6)
        u[dofs] = u_f
        return u

    def gradient(u_f: np.ndarray, s: np.ndarray, active: np.ndarray) -> np.ndarray:
        grad = np.einsum("ij,j->i", cols, np.where(active, s, 0.0)) - load_f
        if shear is not None:
            grad = grad + shear.generalised_force(full(u_f), active[:n_shear])[dofs]
        return grad

    def energy(u_f: np.ndarray, approach: np.ndarray, active: np.ndarray, phi: np.ndarray | None = None) -> tuple[float, float]:
        """Pi(u) and the size of the terms it sums (its round-off scale); ``phi``: the elements'
        energies at ``approach`` if already known."""
        stored = float((law.energy(approach) if phi is None else phi).sum())
        if shear is not None:
            f = shear.force(full(u_f), active[:n_shear])
            stored += 0.5 * float((np.einsum("ij,ij->i", f, f) / np.maximum(shear.stiffness_n_per_mm, 1e-300)).sum())
        work = float(load_f @ u_f)
        return stored - work, stored + abs(work)

    def stiffness(k: np.ndarray, active: np.ndarray) -> np.ndarray:
        hessian = np.einsum("ik,jk->ij", cols * (k * active), cols)
        if shear is not None:
            hessian = hessian + shear.stiffness(active[:n_shear])[np.ix_(dofs, dofs)]
        return hessian

    # fixed over the solve; none for linear elements (no call, no array of inf)
    max_approach = None if isinstance(law, LinearElements) else law.max_approach_mm()
    bounded = max_approach is not None and bool(np.isfinite(max_approach).any())
    u_f = np.zeros(dofs.size)
    approach = np.zeros(m)  # g_j . u, advanced with u (no product with all the rows per step)
    warm = start_displacement is not None
    if warm:
        u_f = np.asarray(start_displacement, float)[dofs]
        approach = np.einsum("i,ij->j", u_f, cols)
        if bounded and not np.all(approach < max_approach):  # a log element crushed there: from u = 0
            warm, u_f, approach = False, np.zeros(dofs.size), np.zeros(m)
    s, k = law.force_and_stiffness(approach)
    active = s > 0 if warm else np.ones(m, bool)
    seen: set[bytes] = set()
    # From the second iteration on, active == (s > 0) and this is the previous residual: reused.
    grad = gradient(u_f, s, active)
    load_norm = _norm(load_f * to_newton_f)
    # Pi at the current u when the last line search evaluated it there (no shear: Pi then does
    # not depend on the active set the search used).
    known_energy: tuple[float, float] | None = None
    for iteration in range(1, max_iterations + 1):
        hessian = stiffness(k, active)
        step = _regular_solve(hessian, dof_scale, -grad)
        if step is None and iteration == 1 and warm:
            # The elements compressed at the start leave a DOF free: start from u = 0 as DEM does.
            u_f, approach, active = np.zeros(dofs.size), np.zeros(m), np.ones(m, bool)
            s, k = law.force_and_stiffness(approach)
            grad = gradient(u_f, s, active)
            hessian = stiffness(k, active)
            step = _regular_solve(hessian, dof_scale, -grad)
        if step is None:
            everything = assemble_stiffness(directions, k, np.ones(m, bool), shear)
            missing = unrestrained_dofs(everything, free, length_scale_mm)
            if missing:
                raise singular_stiffness_error(missing)
            if not np.any(active):
                raise SolverError(
                    "no equilibrium: no spring stays in compression under this load, so the load pulls "
                    "the bodies apart (or pushes along a direction no spring resists)"
                )
            # A transiently small active set: regularise with a trace of every element's stiffness.
            hessian = hessian + 1e-8 * everything[np.ix_(dofs, dofs)]
            step = -np.linalg.solve(hessian, grad)
        rate = np.einsum("i,ij->j", step, cols)  # d(approach)/d(alpha)
        alpha = 1.0
        if bounded:  # fraction to the boundary of the log elements' admissible approaches
            room = max_approach - approach
            alpha = min(1.0, float(np.min(0.99 * room[rate > 0] / rate[rate > 0], initial=np.inf)))
        slope = float(grad @ step) if iteration > 1 else 0.0
        known, known_energy = known_energy, None
        accepted = None  # (approach, s, k) of the accepted line-search trial
        if slope < 0.0:
            # Armijo on Pi. The first step is taken whole: all active (DEM's), with non-negative
            # offsets, it descends anyway (Pi <= the all-active quadratic it minimises); from a
            # given start it is a plain Newton step on Pi, the next iterations are damped.
            # (From the second iteration on, active == (s > 0): the compressed elements.)
            e0, size = known if known is not None else energy(u_f, approach, active)
            # Differences below the energy's round-off say nothing: the step is then taken.
            noise = 1e-12 * size
            while alpha > 1e-12:
                trial_approach = approach + alpha * rate
                trial_s, trial_k, trial_phi = law.force_stiffness_energy(trial_approach)
                trial = energy(u_f + alpha * step, trial_approach, active, trial_phi)
                if trial[0] <= e0 + 1e-4 * alpha * slope + noise:
                    known_energy = trial if shear is None else None
                    accepted = trial_approach, trial_s, trial_k
                    break
                alpha *= 0.5
        u_f = u_f + alpha * step
        if accepted is not None:  # the trial's approaches, forces and stiffnesses are the step's
            approach, s, k = accepted
        else:
            approach = approach + alpha * rate
            s, k = law.force_and_stiffness(approach)
        new_active = s > 0
        residual = gradient(u_f, s, new_active)
        # Force scale of the problem: the load and every element force (incl. the stored ones).
        reference = load_norm + float(np.abs(s).sum())
        residual_norm = _norm(residual * to_newton_f)
        if residual_norm <= rtol * max(reference, 1e-300):
            active = new_active
            break
        # A spring whose force is zero to round-off can flip in and out of the active set for ever:
        # once a set comes back, accept the iterate if it balances the load to a looser tolerance.
        signature = np.packbits(new_active).tobytes()
        cycled = signature in seen and not np.array_equal(new_active, active)
        if cycled and residual_norm <= cycle_rtol * reference:
            active = new_active
            break
        seen.add(signature)
        if not new_active.any():
            raise SolverError(
                "no equilibrium: no spring stays in compression under this load, so the load pulls "
                "the bodies apart"
            )
        active = new_active
        grad = residual
    else:
        if not balanceable(directions, load, free, to_newton):
            raise SolverError(
                "no equilibrium: compression-only springs cannot balance this load (its line of "
                "action passes outside the region where the bodies can touch, or it pulls them apart)"
            )
        raise SolverError(
            f"the active-set iteration did not converge in {max_iterations} iterations "
            f"(residual {residual_norm:.3e} N)"
        )
    u = full(u_f)
    residual = full(residual)
    return UnilateralSolution(
        displacement=u,
        element_force_n=s,
        active=active,
        iterations=iteration,
        force_residual_n=_norm(residual[:3]),
        moment_residual_nmm=_norm(residual[3:]),
    )
