"""The inner linear solve of the bordered Newton (:mod:`fem_reference.contact`): MUMPS LU, or
past the LU's memory a preconditioned Krylov method (docs/method.md#6-the-fe-reference-and-its-discrete-twins, "Linear solver").

* :class:`InnerSolver`: the KSP that solves with the elastic block A of each Newton step, set up
  by :func:`use_iterative`: LU, or Krylov with :func:`krylov_amg` (P1, P2) or
  :func:`krylov_fieldsplit` (Taylor-Hood); it counts the Krylov iterations and refuses a solve
  that does not converge.
* :func:`krylov_amg`: CG / GMRES with PETSc GAMG and the rigid-body near-nullspace
  (:func:`near_nullspace`), :data:`GAMG_OPTIONS`.
* :func:`krylov_fieldsplit`: GMRES with a Schur-complement field split (u, p).

Heavy imports (petsc4py, dolfinx, ufl) happen inside the functions (:mod:`fem_reference.fe_stack`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .problem import FEConvergenceError

if TYPE_CHECKING:
    from .contact_setup import ContactSetup


def use_iterative(s: ContactSetup) -> bool:
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


def rigid_body_modes(coords: np.ndarray, like: Any) -> list:
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


def near_nullspace(s: ContactSetup, coords: np.ndarray, like: Any) -> Any:
    """The rigid-body modes at ``coords`` as an orthonormal PETSc near-nullspace."""
    PETSc = s.m["PETSc"]
    modes = rigid_body_modes(coords, like)
    for j, vec in enumerate(modes):  # Gram-Schmidt: a PETSc null space has an orthonormal basis
        for prev in modes[:j]:
            vec.axpy(-vec.dot(prev), prev)
        vec.normalize()
    return PETSc.NullSpace().create(vectors=modes, comm=s.comm)


def set_inner_options(ksp: Any, options: dict[str, str]) -> list[str]:
    """Put ``options`` in the PETSc database under the inner solver's prefix and read them.
    They stay there until the solve ends (:meth:`InnerSolver.destroy` removes the returned keys): the
    multigrid levels and the field-split blocks read theirs when the preconditioner is set up."""
    from petsc4py import PETSc

    db = PETSc.Options()
    keys = [f"{ksp.getOptionsPrefix()}{key}" for key in options]
    for key, val in zip(keys, options.values()):
        db[key] = val
    ksp.setFromOptions()
    return keys


def krylov_amg(ksp: Any, A: Any, s: ContactSetup) -> list[str]:
    """P1/P2: CG (symmetric Nitsche, theta = 1) or right-preconditioned GMRES with GAMG and the
    rigid-body near-nullspace on the blocked (3 per node) displacement."""
    nodes = s.V.dofmap.index_map.size_local
    vec, _ = A.createVecs()
    A.setNearNullSpace(near_nullspace(s, s.V.tabulate_dof_coordinates()[:nodes], vec))
    vec.destroy()
    options = {"pc_type": "gamg", **GAMG_OPTIONS}
    if s.problem.nitsche.theta == 1.0:
        options["ksp_type"] = "cg"
    else:
        options.update(ksp_type="gmres", ksp_gmres_restart=str(GMRES_RESTART), ksp_pc_side="right")
    ksp.setTolerances(rtol=INNER_RTOL, atol=0.0, max_it=INNER_MAX_IT)
    return set_inner_options(ksp, options)


def krylov_fieldsplit(ksp: Any, s: ContactSetup) -> tuple[list, list[str]]:
    """Taylor-Hood: right-preconditioned GMRES with a Schur-complement field split (u, p).

    Displacement block: one GAMG cycle with the rigid-body near-nullspace (its IS ordered node by
    node, block size 3); it holds the Nitsche contact terms in u. Pressure (Schur complement
    S = A_pp - A_pu A_uu^-1 A_up, negative definite): approximated by -(1/mu + 1/lambda) M_p,
    the pressure mass matrix scaled like the inverse shear stiffness plus the compressible term
    (-M_p / lambda is A_pp itself; div A_uu^-1 div^T is spectrally M_p / mu on inf-sup stable
    elements), one Jacobi sweep on it. Full factorisation (lower, Schur, upper).

    Returns the PETSc objects the solve keeps (index sets, the pressure matrix) and the option
    keys set, for :meth:`InnerSolver.destroy`."""
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
    nsp = near_nullspace(s, V0.tabulate_dof_coordinates()[:nu_owned], like)
    like.destroy()
    is_u.compose("nearnullspace", nsp)
    p, q = ufl.TrialFunction(Q), ufl.TestFunction(Q)
    scale = -(1.0 / s.mu + 1.0 / s.lam)  # UFL: constants, or per-cell values (two layers)
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
    return [is_u, is_p, nsp, Mp], set_inner_options(ksp, options)


class InnerSolver:
    """The solve with the elastic block A of each Newton step (bonded and roller rows identity):
    one MUMPS LU factorisation, or a Krylov method when :func:`use_iterative` says so
    (:func:`krylov_fieldsplit` for Taylor-Hood, :func:`krylov_amg` otherwise).

    ``A``: the PETSc matrix the Newton loop assembles (its near-nullspace is set here on the
    GAMG path); ``prefix``: the solve's options prefix (this KSP's is ``prefix + "inner_"``).
    """

    def __init__(self, s: ContactSetup, A: Any, prefix: str) -> None:
        PETSc = s.m["PETSc"]
        self.ksp = PETSc.KSP().create(s.comm)
        self.ksp.setOptionsPrefix(f"{prefix}inner_")
        self.element = s.element
        self.iterative = use_iterative(s)
        self.iterations = 0  # Krylov iterations over all solves
        self.keep: list = []  # PETSc objects of the preconditioner, destroyed with the solver
        self.option_keys: list[str] = []  # its entries in the PETSc options database, likewise
        if not self.iterative:
            self.ksp.setType("preonly")
            pc = self.ksp.getPC()
            pc.setType("lu")
            pc.setFactorSolverType("mumps")
            self.ksp.setFromOptions()
        elif s.element == "TH":
            self.keep, self.option_keys = krylov_fieldsplit(self.ksp, s)
        else:
            self.option_keys = krylov_amg(self.ksp, A, s)

    @property
    def method(self) -> str:
        """The Krylov method and preconditioner, as progress lines name them (``gmres+gamg``...)."""
        return f"{self.ksp.getType()}+{'fieldsplit' if self.element == 'TH' else 'gamg'}"

    def set_operator(self, A: Any) -> None:
        """Factor (LU) or set up the preconditioner of the newly assembled ``A``."""
        self.ksp.setOperators(A)
        self.ksp.setUp()

    def solve(self, b: Any, x: Any) -> None:
        """x = A^-1 b; raises :class:`FEConvergenceError` naming the Krylov method when the
        Krylov solve does not converge in :data:`INNER_MAX_IT` iterations."""
        self.ksp.solve(b, x)
        if not self.iterative:
            return
        self.iterations += self.ksp.getIterationNumber()
        if self.ksp.getConvergedReason() <= 0:
            raise FEConvergenceError(
                f"the inner Krylov solve ({self.ksp.getType()} + {self.ksp.getPC().getType()}) did not converge",
                reason=str(self.ksp.getConvergedReason()), residual_norm=self.ksp.getResidualNorm(),
                iterations=self.ksp.getIterationNumber())

    def destroy(self) -> None:
        """Destroy the KSP and the preconditioner's objects and remove its options."""
        from petsc4py import PETSc

        self.ksp.destroy()
        for obj in self.keep:
            obj.destroy()
        db = PETSc.Options()
        for key in self.option_keys:
            del db[key]
