"""Force-controlled frictionless FE contact of a bonded elastic body against a rigid obstacle.

Small-strain linear elasticity (P1, P2 or Taylor-Hood P2-P1 u-p), unilateral frictionless
contact by Nitsche's method (Chouly-Hild form), and the rigid bone translation as extra unknowns
of the same Newton loop (:func:`solve_contact`).

Formulation (see :mod:`fem_reference.problem` for the sign conventions). The displacement is
split as ``u = u~ + sum_j t_j E_j`` where ``E_j`` is the constant field equal to the free
direction ``e_j`` and ``u~ = 0`` on the bonded face (and on the roller components). A constant
field has no strain, so testing the weak form with ``E_j`` leaves only the contact term:
``F(u; E_j) = e_j . F_c`` with ``F_c`` the force on the obstacle. The extra equations are thus
exactly the force balance ``e_j . (F_c - force_n) = 0``. Newton solves the bordered system

    [ A    K ] [du~]   [R~]          A = dR~/du~ (bonded/roller rows = identity)
    [ G^T  H ] [dt ] = [r ],         K_j = dR~/dt_j, G_j = dr_j/du~, H = dr/dt

with PETSc SNES (newtonls) through a shell matrix and an exact block-elimination
preconditioner: per iteration one set-up of the inner solve with A and k + 1 solves with it
(:class:`fem_reference.krylov.InnerSolver`: a MUMPS factorisation, or past the LU's memory a
preconditioned Krylov method).

The pieces around it: the shared set-up of the problem (spaces, conditions, obstacle, result)
is :class:`fem_reference.contact_setup.ContactSetup`; the inner linear solve
:mod:`fem_reference.krylov`; the variational-inequality cross-check
:func:`fem_reference.contact_vi.solve_contact_vi`; the FE stack's lazy imports
:mod:`fem_reference.fe_stack`.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from .contact_setup import ContactSetup
from .fe_stack import fe_modules, options_prefix, snes_reason_name
from .krylov import InnerSolver
from .problem import AREA_DEFINITION_NITSCHE, FEContactProblem, FEContactResult, FEConvergenceError
from .progress import SolveProgress

#: The inner solves' forcing term on the iterative path (:meth:`BorderedSystem._forcing`): its
#: range while the contact set settles, and the tightest solve tried to finish Newton in one step.
#: Measured 2026-11-28: on the subject-like ankle's slab at 1.0 mm (P2) plain Eisenstat-Walker
#: (forcing down to 1e-12) took 8 Newton steps and 82 Krylov iterations. With these, on the
#: two-layer subject-standing at 1.0 mm (P2, 141k DOFs) 10 Newton steps and 95 Krylov iterations
#: (the LU 6 Newton steps), the LU's answer to 3e-9 % in half its time (benchmarks/bench_fe_iterative.py).
ETA_MAX = 1e-2
ETA_SETTLING = 1e-3
ETA_FINISH = 1e-5

#: The factor the penetration beyond first touch (along the load) may change by per Newton step
#: (:meth:`BorderedSystem.step_limit`), and the approach step of an iterate that touches nowhere.
PENETRATION_GROWTH = 4.0


class BorderedSystem:
    """Residual, Jacobian (shell) and exact block preconditioner of the bordered Newton system."""

    def __init__(self, s: ContactSetup, uh: Any, ut: Any, E: list, forms: dict, prefix: str) -> None:
        self.s = s
        self.uh, self.ut, self.E = uh, ut, E
        self.f = forms
        self.rank = s.comm.rank
        self.k = s.k
        self.no = s.n_owned
        self.Eo = [e.x.array[: self.no].copy() for e in E]
        self.Ea = [e.x.array.copy() for e in E]
        self.load_free = s.gen_load
        self.delta = np.zeros(self.k)
        offset = s.V.dofmap.index_map.local_range[0] * s.V.dofmap.index_map_bs
        self.cons_global = (offset + s.cons_owned).astype(s.m["PETSc"].IntType)
        self.E_vecs = [e.x.petsc_vec for e in E]
        self.A_bulk: Any = None
        self.A = self._create_matrix()
        self.A.setOptionsPrefix(f"{prefix}A_")
        self.inner = InnerSolver(s, self.A, prefix)
        self.wu, self.zu = self.A.createVecs()
        self.K = [np.zeros(self.no) for _ in range(self.k)]
        self.G = [np.zeros(self.no) for _ in range(self.k)]
        self.Xs = [np.zeros(self.no) for _ in range(self.k)]
        # Y_j = A^-1 L_j (the next step's start), L_j, their residual norms and Ef_j (_jacobian)
        self.X_vecs = [self.A.createVecRight() for _ in range(self.k)]
        self.L_vecs = [self.A.createVecRight() for _ in range(self.k)]
        self.Y_residual = np.zeros(self.k)
        self.Ef = [np.zeros(self.no) for _ in range(self.k)]
        self.H = np.zeros((self.k, self.k))
        self.S = np.eye(self.k)
        self.S_ref: np.ndarray | None = None
        self.singular_steps = 0
        self.error: Exception | None = None
        self.limited_steps = 0
        self.ehat: np.ndarray | None = None  # set with t_touch to enable the step limit
        self.t_touch = 0.0
        self.touching = True  # whether the iterate has a point in the contact set (_jacobian)
        self.approach: np.ndarray | None = None  # the rigid step of an untouching start (_approach_step)
        # the iterative path: the inner solves' forcing term and the Krylov iterations per Newton step
        self.newton_tolerances = (0.0, 0.0)  # SNES's (rtol, atol): it stops at max(atol, rtol |F_0|)
        self.fnorm = self.fnorm_previous = self.fnorm_first = float("nan")
        self.eta = ETA_MAX  # this Newton step's
        self.krylov_per_step: list[int] = []  # Krylov iterations of each Newton step (iterative path)

    @staticmethod
    def forms(s: ContactSetup, bulk: Any, contact: Any, uh: Any, E: list, pressure: Any, nu: Any) -> dict:
        """The compiled forms this system assembles from the residual R = ``bulk`` + ``contact``
        (test function and trial direction of ``uh``'s space): the bulk part is linear in u, so
        its matrix is assembled once (``bulk``: its Jacobian) and each Newton step assembles the
        contact facets alone (``F``, ``J``). The borders K, G, H are products of the Jacobian
        with the rigid modes (:meth:`_assemble_jacobian`); ``touching``: :meth:`touching_form`."""
        fem, ufl = s.m["fem"], s.m["ufl"]
        du = ufl.TrialFunction(s.V)
        return {"bulk": fem.form(ufl.derivative(bulk, uh, du)), "F": fem.form(contact),
                "J": fem.form(ufl.derivative(contact, uh, du)), "touching": BorderedSystem.touching_form(s, pressure)}

    @staticmethod
    def touching_form(s: ContactSetup, pressure: Any) -> Any:
        """The area of the contact facets where the contact pressure is positive (mm^2, at the
        quadrature points): zero when the iterate touches nowhere, and then the contact terms
        carry no stiffness against the rigid modes (their part of K, G, H is zero), so the Schur
        complement S is only the round-off of E^T J E - G^T A^-1 K, whose sign is arbitrary
        (:meth:`_jacobian`)."""
        fem, ufl = s.m["fem"], s.m["ufl"]
        return fem.form(ufl.conditional(ufl.gt(pressure, 0.0), 1.0, 0.0) * s.ds_c)

    def _create_matrix(self) -> Any:
        """The PETSc matrix A the Jacobian is assembled into: the bulk's sparsity (the contact
        facets' couplings are within their cells). Assembles the bulk matrix ``A_bulk``."""
        self.A_bulk = self.s.m["fem_petsc"].assemble_matrix(self.f["bulk"])
        self.A_bulk.assemble()
        return self.A_bulk.duplicate(copy=False)

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

    def solve_A(self, rhs: np.ndarray, rtol: float) -> np.ndarray:
        """A^-1 rhs, exact (LU) or to ``rtol`` (Krylov, from zero)."""
        self._load(rhs)
        self.krylov_per_step[-1] += self.inner.solve(self.wu, self.zu, rtol=rtol)
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

    def _residual_vector(self) -> np.ndarray:
        """The owned residual R(u) at the current state (before the bonded rows are set): the
        contact facets' part assembled, the bulk part A_bulk u."""
        self.A_bulk.mult(self.uh.x.petsc_vec, self.zu)
        return self.s.vector_owned(self.f["F"]) + self.zu.getArray(readonly=True)

    def _residual(self, X: Any, F: Any) -> None:
        self.set_state(X)
        b = self._residual_vector()
        r = np.array([self.dot(self.Eo[j], b) for j in range(self.k)]) - self.load_free
        b[self.s.cons_owned] = self.ut.x.array[self.s.cons_owned]
        self.join(F, b, r)
        self.fnorm = F.norm()

    def _assemble_jacobian(self) -> None:
        """A (bonded and roller rows and columns identity), K, G (zero on those rows) and H at the
        current state, all from one assembly of the Jacobian J: u = u~ + sum_j t_j E_j, so
        K_j = J E_j, G_j = J^T E_j and H = E^T J E (the rigid modes E as vectors)."""
        s, fp = self.s, self.s.m["fem_petsc"]
        self.A_bulk.copy(self.A, structure=s.m["PETSc"].Mat.Structure.SAME_NONZERO_PATTERN)
        fp.assemble_matrix(self.A, self.f["J"])  # adds the contact facets' terms
        self.A.assemble()
        self._borders()

    def _borders(self) -> None:
        """K_j = J E_j, G_j = J^T E_j (both zero on the bonded and roller rows) and H = E^T J E
        from the assembled Jacobian J = A; then A's bonded and roller rows and columns identity."""
        cons = self.s.cons_owned
        JE = []
        for j, e in enumerate(self.E_vecs):
            self.A.mult(e, self.zu)
            JE.append(np.array(self.zu.getArray(readonly=True)))
            self.A.multTranspose(e, self.zu)
            self.G[j] = np.array(self.zu.getArray(readonly=True))
            self.G[j][cons] = 0.0
        for j in range(self.k):
            for m_ in range(self.k):
                self.H[j, m_] = self.dot(self.Eo[j], JE[m_])
            self.K[j] = JE[j]
            self.K[j][cons] = 0.0
        self.A.zeroRowsColumns(self.cons_global, diag=1.0)

    def _jacobian(self, X: Any, J: Any) -> None:
        self.set_state(X)
        self._assemble_jacobian()
        self.inner.set_operator(self.A)
        self._forcing()
        self.krylov_per_step.append(0)
        # Touching nowhere, S = H - G^T A^-1 K is zero but for round-off: E^T J E holds the bulk's
        # E^T A_bulk E, zero only to round-off (-6e-14 on a 4 x 4 x 1 mm slab; either sign), and a
        # negative S steps away from the obstacle. A start that touches nowhere (the touching
        # estimate's penetration between the contact facets' quadrature points) approaches along
        # the load instead; a later iterate keeps the last regular S (_schur).
        self.touching = self.s.scalar(self.f["touching"]) > 0.0
        self.approach = None if self.touching or self.S_ref is not None else self._approach_step()
        if self.approach is not None:
            J.assemble()
            return
        for j in range(self.k):
            # X_j = A^-1 K_j = Ef_j + A^-1 L_j with Ef_j the rigid mode zero on the bonded rows and
            # L_j = K_j - A Ef_j the elastic force of moving the bonded face alone (K_j holds the
            # contact stiffness, whose scale the error of an inexact solve would take)
            self.Ef[j] = self.Eo[j].copy()
            self.Ef[j][self.s.cons_owned] = 0.0
            self._load(self.Ef[j])
            self.A.mult(self.wu, self.zu)
            with self.L_vecs[j] as arr:
                arr[:] = self.K[j] - self.zu.getArray(readonly=True)
            self._solve_Y(j, self.eta)
        self._schur(initial=True)
        J.assemble()

    def _solve_Y(self, j: int, rtol: float) -> None:
        """Y_j = A^-1 L_j, exact (LU) or to ``rtol`` from the last one (the last Newton step's);
        X_j = Ef_j + Y_j and the residual norm |L_j - A Y_j| that the step's accuracy needs."""
        self.krylov_per_step[-1] += self.inner.solve(self.L_vecs[j], self.X_vecs[j], rtol=rtol, guess=True)
        self.Y_residual[j] = self.inner.ksp.getResidualNorm() if self.inner.iterative else 0.0
        self.Xs[j] = self.Ef[j] + self.X_vecs[j].getArray(readonly=True)

    def _schur(self, initial: bool) -> None:
        """S = H - G^T X, the tangent contact stiffness of the free rigid motions. It is singular
        when an iterate has lost contact: then the last regular one (counted once per step,
        ``initial``)."""
        S = self.H - np.array([[self.dot(self.G[j], self.Xs[m_]) for m_ in range(self.k)]
                               for j in range(self.k)])
        sv = np.linalg.svd(S, compute_uv=False)
        if self.S_ref is None:  # touching (_jacobian)
            if sv.min() <= 1e-12 * max(sv.max(), 1e-300):
                raise FEConvergenceError(
                    "no contact stiffness along (a combination of) the free translations at the "
                    "initial state: either the contact surface does not touch the obstacle, or "
                    "frictionless contact cannot resist a free translation tangent to the "
                    "obstacle (fix that translation through free_dofs)", reason="NO_CONTACT")
            self.S_ref = S.copy()
        ref = np.linalg.svd(self.S_ref, compute_uv=False).max()
        if not self.touching or sv.min() <= 1e-8 * ref:
            self.singular_steps += int(initial)
            S = self.S_ref.copy()
        else:
            self.S_ref = S.copy()
        self.S = S

    def mult(self, mat: Any, x: Any, y: Any) -> None:
        xu, xd = self.split(x)
        self._load(xu)
        self.A.mult(self.wu, self.zu)
        yu = np.array(self.zu.getArray(readonly=True))
        for j in range(self.k):
            yu += xd[j] * self.K[j]
        yd = np.array([self.dot(self.G[j], xu) for j in range(self.k)]) + self.H @ xd
        self.join(y, yu, yd)

    def eliminate(self, z0: np.ndarray, xd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The block elimination's last steps, given z0 = A^-1 x_u: dd = S^-1 (x_d - G^T z0),
        y_u = z0 - X dd with X = A^-1 K. With inexact z0 and X (Krylov to the forcing term) the
        rigid rows of the bordered system still hold exactly (S = H - G^T X with the X used), and
        its u rows are off by the residuals of those solves: an inexact Newton step."""
        rhs = xd - np.array([self.dot(self.G[j], z0) for j in range(self.k)])
        dd = np.linalg.solve(self.S, rhs)
        yu = z0
        for j in range(self.k):
            yu = yu - dd[j] * self.Xs[j]
        return yu, dd

    def _forcing(self) -> None:
        """The relative tolerance of this Newton step's inner Krylov solves.

        Eisenstat and Walker's choice 2, 0.9 (|F_k| / |F_k-1|)^2, kept within [:data:`ETA_SETTLING`,
        :data:`ETA_MAX`] while the contact set settles: a semi-smooth Newton step whose active set
        changes reduces |F| by 0.1-0.8 whatever the solve's accuracy, so a tighter solve is
        wasted. A step that did what its linear model promised (|F| reduced to within twice its
        forcing term: the active set held) says the problem is linear from here: the next step is
        solved to finish (|F| to half the Newton tolerance, tolerance / |F| / 2) when that is not
        below :data:`ETA_FINISH`. Never tighter than a tenth of the Newton tolerance over |F|."""
        if not np.isfinite(self.fnorm_first):
            self.fnorm_first = self.fnorm
        target = max(self.newton_tolerances[1], self.newton_tolerances[0] * self.fnorm_first)
        eta = ETA_MAX
        if np.isfinite(self.fnorm_previous) and self.fnorm_previous > 0.0 and self.fnorm > 0.0:
            ratio = self.fnorm / self.fnorm_previous
            eta = min(ETA_MAX, max(0.9 * ratio**2, ETA_SETTLING))
            finish = 0.5 * target / self.fnorm
            if ratio <= 2.0 * self.eta and finish >= ETA_FINISH:
                eta = min(eta, finish)
        self.eta = float(max(eta, 0.1 * target / self.fnorm if self.fnorm > 0.0 else eta))
        self.fnorm_previous = self.fnorm

    def _approach_step(self) -> np.ndarray:
        """The rigid step (k,) of a start that touches nowhere: along the load, the penetration
        beyond first touch grown by :data:`PENETRATION_GROWTH` (the step limit's largest step; in
        SNES's sign, X <- X - Y). With no contact term the bulk rows of the bordered system do not
        depend on the rigid unknowns (K = 0), so its u~ rows are solved as they stand."""
        kt = self.s.kt
        along = self.s.dirs @ self.ehat if self.ehat is not None else np.zeros(kt)  # (kt,)
        pen = float(along @ self.delta[:kt]) - self.t_touch
        if pen <= 0.0 or float(along @ along) == 0.0:
            raise FEConvergenceError(
                "the contact surface does not touch the obstacle at the initial state (no contact "
                "pressure on the contact facets, and the start is not beyond first touch along the "
                "load)", reason="NO_CONTACT")
        dd = np.zeros(self.k)
        dd[:kt] = -(PENETRATION_GROWTH - 1.0) * pen * along / float(along @ along)
        return dd

    def apply(self, pc: Any, x: Any, y: Any) -> None:
        xu, xd = self.split(x)
        z0 = self.solve_A(xu, self.eta)
        if self.approach is not None:
            self.join(y, z0, self.approach)
            return
        yu, dd = self.eliminate(z0, xd)
        # The step's residual in the u rows is r(z0) - sum_j dd_j r(Y_j): the Y_j were solved to the
        # forcing term of |L_j|, which can be far larger than |F| / |dd_j|. Solve them further
        # until that part is within half the forcing term of |F| (the LU's are exact).
        allowed = 0.5 * self.eta * x.norm()
        for _ in range(3):
            excess = np.abs(dd) * self.Y_residual
            if excess.sum() <= allowed:
                break
            for j in np.flatnonzero(excess > allowed / self.k):
                target = 0.5 * allowed / (self.k * abs(dd[j]))
                self._solve_Y(j, max(target / max(self.L_vecs[j].norm(), 1e-300), 1e-14))
            self._schur(initial=False)
            yu, dd = self.eliminate(z0, xd)
        alpha = self.step_limit(dd)
        if alpha < 1.0:
            yu, dd = alpha * yu, alpha * dd
            self.limited_steps += 1
        self.join(y, yu, dd)

    def step_limit(self, dd: np.ndarray) -> float:
        """Damping factor keeping the penetration beyond first touch (along the load) within a
        factor :data:`PENETRATION_GROWTH` of the current one per Newton step (SNES steps X <- X - Y)."""
        if self.ehat is None:
            return 1.0
        growth = PENETRATION_GROWTH
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

    def release(self) -> None:
        """Destroy the inner solver, A and the work vectors. (Not ``destroy``: petsc4py calls a
        Python preconditioner context's ``destroy(pc)`` when the PC goes.)"""
        self.inner.destroy()
        self.A.destroy()
        if self.A_bulk is not None:
            self.A_bulk.destroy()
        for vec in (self.wu, self.zu, *self.X_vecs, *self.L_vecs):
            vec.destroy()


#: The set-up and bordered system of an obstacle that is not rigid, by its type (the rigid ones
#: use :class:`ContactSetup` and :class:`BorderedSystem`); registered by the module that solves it:
#: :class:`fem_reference.problem.DeformableCounterpart` by :mod:`fem_reference.two_body`.
OBSTACLE_SOLVERS: dict[type, tuple[type, type]] = {}


class _ShellContext:
    def __init__(self, system: BorderedSystem) -> None:
        self.system = system

    def mult(self, mat: Any, x: Any, y: Any) -> None:
        self.system.mult(mat, x, y)


#: Solves of a problem whose pairing follows the slip (a deformable F,
#: :meth:`fem_reference.two_body.TwoBodySetup.moved_pairing`) before the pairing is left as it is
#: (with a warning); 2-3 were needed on the verification cases.
MAX_PAIRING_PASSES = 10


def nitsche_modulus_mpa(element: str, lam_mpa: float, mu_mpa: float, *, own_bulk: bool = False) -> float:
    """The modulus Nitsche's penalty gamma0 E / h scales with (MPa): the stiffness of the stress's
    displacement part.

    P1 / P2: lambda + 2 mu. Taylor-Hood elasticity (sigma = 2 mu eps(u) - p I): 2 mu, the pressure
    being its own unknown; with lambda + 2 mu the penalty grows like 1 / (1 - 2 nu) against the
    shear stiffness and locks the contact face of a confined layer (on the subject-like ankle at nu
    0.499 the contact area on M was 380 / 328 / 413 mm^2 at 2.0 / 1.0 / 0.7 mm and Newton did not
    converge at 0.4999 by LU; with 2 mu 518 / 509 / 517 mm^2, and the field split's iterations no
    longer grow with lambda / mu; docs/method.md#the-iterative-path). A time scheme's own bulk
    terms (``own_bulk``, the biphasic matrix: sigma_e(u) = lambda tr eps I + 2 mu eps, the pore
    pressure apart) keep lambda + 2 mu, lambda being the drained matrix's.
    """
    return 2.0 * mu_mpa if element == "TH" and not own_bulk else lam_mpa + 2.0 * mu_mpa


def solve_contact(problem: FEContactProblem, comm: Any = None, *,
                  keep_fields: bool = True, progress: SolveProgress | None = None) -> FEContactResult:
    """Solve ``problem`` by Nitsche contact with force control (bordered semi-smooth Newton).

    ``progress``: progress lines from inside the solve (:mod:`fem_reference.progress`); in
    parallel give one on every rank (rank 0 writes). Against a deformable F whose pairing
    follows the slip, the problem is solved again from the last solution with the pairing of the
    deformed configuration until it stops moving (the result's Newton iterations and wall time
    are those of all passes).

    Raises :class:`FEConvergenceError` when SNES does not converge or the converged solution
    does not balance the load to ``problem.solver.force_balance_rtol``.
    """
    started = time.perf_counter()
    result = _solve(problem, comm, progress)
    newton, passes = result.newton_iterations, 0
    while (moved := result.fields["setup"].moved_pairing(result.fields["solution"])) is not None:
        if passes == MAX_PAIRING_PASSES:
            result.warnings.append(f"the pairing of the two layers still moved after {passes} passes: it is left where "
                                   "the last one put it")
            break
        warm = replace(problem, obstacle=moved, initial_field=result.fields["ut_owned"],
                       initial_translation_mm=result.bone_displacement_mm, initial_rotation_rad=result.bone_rotation_rad)
        try:
            result = _solve(warm, comm, progress)
        except FEConvergenceError:  # the last pass's solution was a bad start: start afresh
            result = _solve(replace(problem, obstacle=moved), comm, progress)
        newton, passes = newton + result.newton_iterations, passes + 1
    result.newton_iterations = newton
    result.wall_time_s = time.perf_counter() - started
    if not keep_fields:
        result.fields = None
    return result


def solve_from_warm_start(problem: FEContactProblem, comm: Any = None, *, progress: SolveProgress | None = None,
                          cold_progress: SolveProgress | None = None) -> FEContactResult:
    """:func:`solve_contact` (fields kept) from the problem's warm start (``initial_translation_mm``,
    ``initial_rotation_rad``, ``initial_field``: a previous time point's solution); a warm start
    that does not converge is a bad start, not a bad problem: the problem is solved again from
    the default start (the warm start cleared; ``cold_progress`` reports that solve)."""
    warm = any(x is not None for x in (problem.initial_translation_mm, problem.initial_rotation_rad, problem.initial_field))
    try:
        return solve_contact(problem, comm, keep_fields=True, progress=progress)
    except FEConvergenceError:
        if not warm:
            raise
        problem.initial_translation_mm = problem.initial_rotation_rad = problem.initial_field = None
        return solve_contact(problem, comm, keep_fields=True, progress=cold_progress)


def _solve(problem: FEContactProblem, comm: Any, progress: SolveProgress | None) -> FEContactResult:
    """One solve of :func:`solve_contact` (its fields kept)."""
    t_start = time.perf_counter()
    m = fe_modules()
    fem, ufl, PETSc, MPI = m["fem"], m["ufl"], m["PETSc"], m["MPI"]
    comm = MPI.COMM_WORLD if comm is None else comm
    element = problem.resolved_element()
    setup, system_class = OBSTACLE_SOLVERS.get(type(problem.obstacle), (ContactSetup, BorderedSystem))
    s = setup(problem, comm, element)
    warnings: list[str] = []
    if element == "P1" and problem.poissons_ratio >= 0.49:
        warnings.append(f"P1 elements lock at nu = {problem.poissons_ratio}: displacements are "
                        "underestimated; use TH or P2")

    uh = fem.Function(s.V, name="displacement")
    ut = fem.Function(s.V)
    w = ufl.TestFunction(s.V)
    E = s.rigid_modes()

    bulk = None
    if problem.bulk_form is not None:  # a time scheme's own bulk terms (FEContactProblem.bulk_form)
        bulk = problem.bulk_form(s, uh, w)
        u, v = bulk.displacement, bulk.test_displacement
        sig_u, sig_v = bulk.stress_u, bulk.stress_v
    elif element == "TH":
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
    modulus = nitsche_modulus_mpa(element, lam, mu, own_bulk=bulk is not None)
    # A Kelvin-Voigt step (gap_scale c0) constrains u = (v + h) / c0: gamma (u . n - gap) is
    # (gamma / c0) (v . n - gap'), so a steady state solves the elastic discrete problem exactly
    gamma = fem.Constant(s.mesh, float(problem.nitsche.gamma0 * modulus / problem.gap_scale)) / h
    theta = fem.Constant(s.mesh, float(problem.nitsche.theta))
    sn_u = ufl.dot(ufl.dot(sig_u, nu), nu)
    sn_v = ufl.dot(ufl.dot(sig_v, nu), nu)
    # along the body's outward normal n = -nu (against a deformable F: relative to F's displacement)
    un, vn = -ufl.dot(s.relative_displacement(u), nu), -ufl.dot(v, nu)
    pressure = ufl.max_value(0.0, gamma * (un - gap) - sn_u)
    contact = (-theta / gamma * sn_u * sn_v - theta / gamma * pressure * sn_v + pressure * vn) * s.ds_c
    if bulk is not None:
        # A time scheme's own bulk terms may switch with the contact set (a biphasic face's drainage)
        # and carry its history, so they are not linear in u alone: they are assembled each Newton
        # step with the contact terms. The part assembled once is then an elastic bilinear form of the
        # same unknowns (its sparsity is the cells'), added once and taken away again here.
        a_int = ufl.inner(sig_u, s.eps(v)) * s.dx
        contact = contact + bulk.residual(pressure) - a_int
    forms = system_class.forms(s, a_int, contact, uh, E, pressure, nu)
    prefix = options_prefix("fecontact")
    system = system_class(s, uh, ut, E, forms, prefix)
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
    system.newton_tolerances = (opt.rtol, opt.atol_rel_to_load * load_norm)
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
    reason_name = snes_reason_name(PETSc, reason)
    last = history[-1] if history else float("nan")
    if reason <= 0:
        _destroy(snes, Jshell, X, Fv, system)
        raise FEConvergenceError(
            f"Nitsche contact Newton did not converge ({element}, {s.n_global + k} dofs, "
            f"theta={problem.nitsche.theta}, gamma0={problem.nitsche.gamma0})",
            reason=reason_name, residual_norm=last, iterations=iters)
    system.set_state(X)
    delta = np.array(system.delta)
    if system.limited_steps and opt.monitor and s.comm.rank == 0:
        print(f"[fem_reference] {system.limited_steps} Newton steps damped by the penetration "
              "limit")
    if system.singular_steps:
        warnings.append(f"{system.singular_steps} Newton iterate(s) lost contact; the last "
                        "regular contact stiffness was used for those steps")

    # ---- post-processing (three compiled forms: force and moment, nodal loads and area, mass) ----
    resultant = _resultant(s, pressure, nu)
    contact_force = resultant[:3]
    force_residual, _ = s.force_split(contact_force)
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
        contact_moment = resultant[3:]
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
    mass = s.vector_owned(fem.form(ufl.TestFunction(Q) * s.ds_c))
    loads = _NodalLoads(s, pressure)
    load_vec = loads.assemble(0.0)[:, 0]
    nq = Q.dofmap.index_map.size_local
    own = np.sort(pdofs[pdofs < nq])
    pnod = np.where(mass[own] > 0, load_vec[own] / np.where(mass[own] > 0, mass[own], 1.0), 0.0)
    coords = Q.tabulate_dof_coordinates()[own]
    p_all = s.gather(pnod)
    x_all = s.gather(coords)
    peak = float(p_all.max()) if len(p_all) else 0.0
    # the P1 hat functions sum to 1: the sums of the nodal integrals are the integrals
    area = s.comm.allreduce(float(loads.assemble(1e-8 * max(peak, 1e-300))[:nq, 1].sum()), op=MPI.SUM)
    total_p = s.comm.allreduce(float(load_vec[:nq].sum()), op=MPI.SUM)
    mean_p = total_p / area if area > 0 else 0.0
    fields = {"mesh": s.mesh, "facet_tags": s.facet_tags, "solution": uh, "pressure": pressure,
              "displacement": u, "space": s.V, "setup": s, "ut_owned": system.ut.x.array[: s.n_owned].copy()}
    result = s.result(
        method="nitsche", area_definition=AREA_DEFINITION_NITSCHE, translation_mm=s.dirs.T @ delta[:s.kt],
        points_mm=x_all, pressure_mpa=p_all, peak_pressure_mpa=peak, mean_pressure_mpa=mean_p,
        contact_area_mm2=area, contact_force_n=contact_force, displacement=u, n_dofs=s.n_global + k,
        newton_iterations=iters, converged_reason=reason_name, started=t_start, warnings=warnings,
        fields=fields, linear_solver="iterative" if system.inner.iterative else "direct",
        krylov_iterations=int(system.inner.iterations), rotation_axes=s.rot.copy(),
        krylov_iterations_per_step=list(system.krylov_per_step) if system.inner.iterative else [],
        bone_rotation_rad=s.rot.T @ delta[s.kt:], contact_moment_nmm=contact_moment,
        moment_residual_nmm=moment_residual)
    _destroy(snes, Jshell, X, Fv, system)
    return result


def _resultant(s: ContactSetup, pressure: Any, nu: Any) -> np.ndarray:
    """(6,) the force the body exerts on the obstacle (N) and its moment about G (N mm), integrated
    over the contact facets in one assembly: a vector form on the piecewise constant (6,) space,
    whose DOFs' sums are the integrals."""
    fem, ufl, MPI = s.m["fem"], s.m["ufl"], s.m["MPI"]
    W = fem.functionspace(s.mesh, ("DG", 0, (6,)))
    traction = -pressure * nu
    arm = ufl.SpatialCoordinate(s.mesh) - fem.Constant(s.mesh, s.ref_point)
    moment = ufl.cross(arm, traction)
    both = ufl.as_vector([traction[i] for i in range(3)] + [moment[i] for i in range(3)])
    vec = s.vector_owned(fem.form(ufl.inner(both, ufl.TestFunction(W)) * s.ds_c))
    return s.comm.allreduce(vec.reshape(-1, 6).sum(axis=0), op=MPI.SUM)


class _NodalLoads:
    """The contact pressure's nodal integrals on the P1 nodes of the contact surface and the
    indicator of where it exceeds a threshold, one compiled form for both: column 0 integral of
    p phi_i, column 1 integral of [p > threshold] phi_i (the contact nodes of the progress lines,
    threshold 0; the contact area, threshold 1e-8 of the peak)."""

    def __init__(self, s: ContactSetup, pressure: Any) -> None:
        fem, ufl = s.m["fem"], s.m["ufl"]
        self.s = s
        self.threshold = fem.Constant(s.mesh, 0.0)
        Q2 = fem.functionspace(s.mesh, ("Lagrange", 1, (2,)))
        both = ufl.as_vector([pressure, ufl.conditional(ufl.gt(pressure, self.threshold), 1.0, 0.0)])
        self.form = fem.form(ufl.inner(both, ufl.TestFunction(Q2)) * s.ds_c)

    def assemble(self, threshold: float) -> np.ndarray:
        """(owned P1 nodes, 2): the two integrals per node (see the class)."""
        self.threshold.value = threshold
        return self.s.vector_owned(self.form).reshape(-1, 2)


def _monitor_progress(snes: Any, system: BorderedSystem, s: ContactSetup, pressure: Any, progress: SolveProgress) -> None:
    """Newton and (iterative path) Krylov monitors writing ``progress`` lines (rank 0).

    The contact nodes are the P1 nodes of the contact surface whose lumped pressure is positive
    at the iterate; counting them is one facet assembly per Newton iteration, on every rank."""
    MPI = s.m["MPI"]
    pdofs, _, Q = s.contact_points(1)
    owned = np.sort(pdofs[pdofs < Q.dofmap.index_map.size_local])
    loads = _NodalLoads(s, pressure)
    previous: list[np.ndarray] = []

    def newton(snes_: Any, it: int, fnorm: float) -> None:
        system.set_state(snes_.getSolution())  # the iterate (set_state only copies it into the fields)
        active = loads.assemble(0.0)[owned, 1] > 0.0
        entered = left = 0
        if previous:
            entered = int(np.count_nonzero(active & ~previous[0]))
            left = int(np.count_nonzero(previous[0] & ~active))
        counts = s.comm.allreduce(np.array([np.count_nonzero(active), entered, left]), op=MPI.SUM)
        previous[:] = [active]
        if s.comm.rank == 0:
            krylov = system.krylov_per_step[-1] if system.inner.iterative and system.krylov_per_step else None
            progress.newton(int(it), float(fnorm), int(counts[0]), int(counts[1]), int(counts[2]), krylov)

    snes.setMonitor(newton)
    if system.inner.iterative and s.comm.rank == 0:
        method = system.inner.method
        system.inner.ksp.setMonitor(lambda _ksp, it, rnorm: progress.krylov(int(it), float(rnorm), method))


def _destroy(*objs: Any) -> None:
    for o in objs:
        if isinstance(o, BorderedSystem):
            o.release()
        elif o is not None:
            o.destroy()

