"""The inner linear solve of the bordered Newton (:mod:`fem_reference.contact`): MUMPS LU, or a
preconditioned Krylov method (docs/method.md#6-the-fe-reference-and-its-discrete-twins, "Linear solver").

* :class:`InnerSolver`: the solve with the elastic block A of each Newton step, set up by
  :func:`use_iterative`: LU, or Krylov with :func:`krylov_amg` (P1), :func:`krylov_pmg` (P2) or
  :func:`krylov_fieldsplit` (Taylor-Hood). One seam for any bordered system: it factors or sets
  up the preconditioner once per operator (:meth:`InnerSolver.set_operator`), solves to a given
  tolerance from a given start (:meth:`InnerSolver.solve`) and applies its preconditioner alone
  (:meth:`InnerSolver.precondition`); it counts the Krylov iterations and refuses a solve that
  does not converge.
* :class:`PMultigrid`: the P2 -> P1 two-level preconditioner (p-multigrid on one mesh): one
  symmetric SOR sweep on P2 before and after a coarse correction on the P1 space of the same mesh,
  whose Galerkin operator P^T A P is solved by one cycle of PETSc GAMG with the rigid-body
  near-nullspace (:func:`near_nullspace`, :data:`GAMG_OPTIONS`).
* :func:`krylov_fieldsplit`: GMRES with a Schur-complement field split (u, p): the p-multigrid on
  u, the pressure mass matrix scaled by -(1/mu + 1/lambda) on p.

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
    from fem_reference.sizing import iterative_is_default

    choice = s.problem.solver.linear_solver
    return choice == "iterative" or (choice == "auto" and iterative_is_default(s.n_global, s.problem.resolved_element()))


#: Relative tolerance of an inner Krylov solve when the caller does not give one, on the
#: unpreconditioned residual (GMRES with right preconditioning): 1e-10 makes it an exact solve for
#: a Newton loop that stops at 1e-10 of its first residual.
INNER_RTOL = 1e-10
#: Inner Krylov iterations before a solve is declared not converged.
INNER_MAX_IT = 1000
#: GMRES restart (PETSc's default is 30; a solve takes 10-60 iterations here, so 200 never
#: restarts). PETSc allocates the Krylov vectors as the iteration reaches them.
GMRES_RESTART = 200

#: GAMG settings (PETSc options under the solver's prefix) for P1 and for the P1 level of the
#: p-multigrid. Threshold: drop graph edges below 5 % of the diagonal before aggregating, so that
#: thin slabs' anisotropic couplings give compact aggregates; 3 Chebyshev-Jacobi smoothing steps
#: per level. Measured on the subject-like ankle (1.4 mm, P2, 73k DOFs): 120-140 iterations per
#: inner solve with the PETSc defaults and GMRES(30) at 1e-12, about 60 with these.
GAMG_OPTIONS = {"pc_gamg_threshold": "0.05", "mg_levels_ksp_type": "chebyshev",
                "mg_levels_pc_type": "jacobi", "mg_levels_ksp_max_it": "3"}

#: The p-multigrid's options (under the prefix of the KSP whose PC it is): one symmetric SOR sweep
#: (PETSc's local symmetric sweep) before and after the coarse correction, and one GAMG cycle on the
#: P1 level whose aggregates are kept over the Newton steps (the pattern does not change, the
#: values a little). Measured 2026-11-28 on the subject-like ankle at 1.0 mm (P2, 94k DOFs, a
#: random right-hand side to 1e-10, GMRES): GAMG on P2 61 iterations and 8.7 s of CPU after a
#: 3-5 s set-up; this 33 iterations and 2.9 s after 0.3 s; 2 Chebyshev-Jacobi steps instead of SOR
#: 45, 2 Chebyshev-SOR 26 (4.7 s), 2 Chebyshev-ILU(0) 21 (3.0 s), 200 LU blocks 30 (3.6 s);
#: an exact (LU) P1 level 31 instead of 33: the P1 level is not what limits it.
PMG_OPTIONS = {"mg_levels_ksp_type": "richardson", "mg_levels_pc_type": "sor",
               "mg_levels_ksp_max_it": "1", "mg_coarse_ksp_type": "preonly",
               "mg_coarse_pc_type": "gamg", "mg_coarse_pc_gamg_reuse_interpolation": "true",
               **{f"mg_coarse_{key}": val for key, val in GAMG_OPTIONS.items()}}


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


def _gmres(options: dict[str, str]) -> dict[str, str]:
    """Right-preconditioned GMRES: its residual norm is the unpreconditioned one the tolerances
    and the Newton step's accuracy (:meth:`fem_reference.contact.BorderedSystem.apply`) are on."""
    return {"ksp_type": "gmres", "ksp_gmres_restart": str(GMRES_RESTART), "ksp_pc_side": "right", **options}


def _cg(options: dict[str, str]) -> dict[str, str]:
    """CG (the symmetric Nitsche variant) on the unpreconditioned residual norm, as GMRES."""
    return {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", **options}


def krylov_amg(ksp: Any, A: Any, s: ContactSetup) -> list[str]:
    """P1: CG (symmetric Nitsche, theta = 1) or right-preconditioned GMRES with GAMG and the
    rigid-body near-nullspace on the blocked (3 per node) displacement."""
    nodes = s.V.dofmap.index_map.size_local
    vec, _ = A.createVecs()
    A.setNearNullSpace(near_nullspace(s, s.V.tabulate_dof_coordinates()[:nodes], vec))
    vec.destroy()
    options = {"pc_type": "gamg", "pc_gamg_reuse_interpolation": "true", **GAMG_OPTIONS}
    options = _cg(options) if s.problem.nitsche.theta == 1.0 else _gmres(options)
    return set_inner_options(ksp, options)


class PMultigrid:
    """The P2 -> P1 two-level preconditioner of a P2 displacement (on its own, or the u block of
    Taylor-Hood) on one mesh.

    Interpolation P: the P1 vector space of the same mesh interpolated into the displacement's P2
    (exact: P1 is a subspace of P2), with the rows of the bonded and roller DOFs emptied, so the
    coarse space lies in the constrained space. The coarse operator is the Galerkin product
    ``P^T A P`` of the whole Newton matrix (the Nitsche contact terms included), computed here with
    ``P`` embedded in the full space (for Taylor-Hood its pressure rows are empty), so that the
    field split's u block and the plain P2 matrix are served alike; its sparsity is computed once.

    ``s``: the set-up (its space, constrained DOFs); ``rows``: for Taylor-Hood the parent index of
    each owned displacement DOF of the collapsed P2 space (None for a plain P2 space).
    """

    def __init__(self, s: ContactSetup, fine: Any, rows: np.ndarray | None) -> None:
        PETSc, fem, fp = s.m["PETSc"], s.m["fem"], s.m["fem_petsc"]
        self.comm = s.comm
        coarse = fem.functionspace(s.mesh, ("Lagrange", 1, (3,)))
        P = fp.interpolation_matrix(coarse, fine)
        P.assemble()
        indptr, cols, vals = P.getValuesCSR()
        owned_fine = P.getLocalSize()[0]
        parent = np.arange(owned_fine) if rows is None else np.asarray(rows[:owned_fine])
        constrained = np.isin(parent, s.cons_owned)
        counts = np.where(constrained, 0, np.diff(indptr))
        keep = np.repeat(~constrained, np.diff(indptr))
        # the interpolation in the fine space's own numbering (the field split's u block)
        self.P = _csr_rows(PETSc, s.comm, P.getSizes(), np.arange(owned_fine), counts, cols[keep], vals[keep], owned_fine)
        P.destroy()
        if rows is None:
            self.P_full = self.P
        else:  # the same rows placed at their parent DOFs of the mixed space
            sizes = ((s.n_owned, PETSc.DECIDE), self.P.getSizes()[1])
            self.P_full = _csr_rows(PETSc, s.comm, sizes, parent, counts, cols[keep], vals[keep], s.n_owned)
        self.Ac: Any = None
        n1 = coarse.dofmap.index_map.size_local
        like = self.P.createVecRight()
        self.nullspace = near_nullspace(s, coarse.tabulate_dof_coordinates()[:n1], like)
        like.destroy()

    def update(self, A: Any) -> Any:
        """The coarse operator P^T A P of the newly assembled ``A`` (sparsity reused)."""
        if self.Ac is None:
            self.Ac = A.PtAP(self.P_full)
            self.Ac.setNearNullSpace(self.nullspace)
        else:
            A.PtAP(self.P_full, result=self.Ac)
        return self.Ac

    def configure(self, pc: Any) -> None:
        """Make ``pc`` (of the KSP whose prefix holds :data:`PMG_OPTIONS`) the two-level cycle with
        the coarse operator of the last :meth:`update`."""
        pc.setType("mg")
        pc.setMGLevels(2)
        pc.setMGInterpolation(1, self.P)
        pc.getMGCoarseSolve().setOperators(self.Ac, self.Ac)

    def destroy(self) -> None:
        for obj in {id(o): o for o in (self.P, self.P_full, self.Ac, self.nullspace) if o is not None}.values():
            obj.destroy()


def _csr_rows(PETSc: Any, comm: Any, sizes: Any, rows: np.ndarray, counts: np.ndarray, cols: np.ndarray,
              vals: np.ndarray, n_rows: int) -> Any:
    """An AIJ matrix of ``sizes`` (local rows ``n_rows``) whose local row ``rows[i]`` holds the i-th
    of the rows given in order by ``counts`` / ``cols`` (global) / ``vals``, the others empty;
    columns in blocks of 3 (the coarse operator P^T A P then has nodal blocks, as GAMG wants)."""
    lengths = np.zeros(n_rows, dtype=np.int64)
    lengths[rows] = counts
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    order = np.argsort(rows, kind="stable")
    # the entries of the given rows in the order of their new positions
    take = (np.repeat(start[order] - np.concatenate([[0], np.cumsum(counts[order])[:-1]]), counts[order])
            + np.arange(int(counts.sum())))
    indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(PETSc.IntType)
    mat = PETSc.Mat().createAIJ(sizes, bsize=(1, 3), comm=comm)
    mat.setPreallocationCSR((indptr, cols[take].astype(PETSc.IntType), vals[take]))
    mat.assemble()
    return mat


def krylov_pmg(ksp: Any, s: ContactSetup) -> tuple[PMultigrid, list[str]]:
    """P2: right-preconditioned GMRES (CG for the symmetric Nitsche, theta = 1) with the
    :class:`PMultigrid` cycle. Returns the multigrid (its coarse operator is updated by
    :meth:`InnerSolver.set_operator`) and the option keys set."""
    mg = PMultigrid(s, s.V, None)
    options = dict(PMG_OPTIONS)
    options = _cg(options) if s.problem.nitsche.theta == 1.0 else _gmres(options)
    return mg, set_inner_options(ksp, options)


def krylov_fieldsplit(ksp: Any, s: ContactSetup) -> tuple[PMultigrid, list, list[str]]:
    """Taylor-Hood: right-preconditioned GMRES with a Schur-complement field split (u, p).

    Displacement block: one :class:`PMultigrid` cycle (its coarse operator holds the Nitsche
    contact terms of u). Pressure (Schur complement S = A_pp - A_pu A_uu^-1 A_up, negative
    definite): approximated by -(1/mu + 1/lambda) M_p, the pressure mass matrix scaled like the
    inverse shear stiffness plus the compressible term (-M_p / lambda is A_pp itself;
    div A_uu^-1 div^T is spectrally M_p / mu on inf-sup stable elements), one Jacobi sweep on it.
    Upper block-triangular factorisation: one u cycle per iteration (measured on the subject-like
    ankle at 1.0 mm, nu 0.49, a random right-hand side to 1e-10: 50 iterations and 4.8 s of CPU,
    against 48 and 7.8 s with the full factorisation's two; lower 54; three Chebyshev or
    Richardson sweeps on M_p instead of one Jacobi: 48, no gain).

    Returns the multigrid of the u block, the PETSc objects the solve keeps (index sets, the
    pressure matrix) and the option keys set, for :meth:`InnerSolver.destroy`."""
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
    p, q = ufl.TrialFunction(Q), ufl.TestFunction(Q)
    scale = -(1.0 / s.mu + 1.0 / s.lam)  # UFL: constants, or per-cell values (two layers)
    Mp = s.m["fem_petsc"].assemble_matrix(fem.form(scale * p * q * s.dx))
    Mp.assemble()
    pc = ksp.getPC()
    pc.setType("fieldsplit")
    pc.setFieldSplitIS(("u", is_u), ("p", is_p))
    pc.setFieldSplitType(PETSc.PC.CompositeType.SCHUR)
    pc.setFieldSplitSchurFactType(PETSc.PC.FieldSplitSchurFactType.UPPER)
    pc.setFieldSplitSchurPreType(PETSc.PC.FieldSplitSchurPreType.USER, Mp)
    mg = PMultigrid(s, V0, u_map)
    # the u block's PC is "none" until the split has made its KSP (InnerSolver.set_operator then
    # makes it the multigrid)
    options = _gmres({"fieldsplit_u_ksp_type": "preonly", "fieldsplit_u_pc_type": "none",
                      **{f"fieldsplit_u_{key}": val for key, val in PMG_OPTIONS.items()},
                      "fieldsplit_p_ksp_type": "preonly", "fieldsplit_p_pc_type": "jacobi"})
    return mg, [is_u, is_p, Mp], set_inner_options(ksp, options)


class InnerSolver:
    """The solve with the elastic block A of each Newton step (bonded and roller rows identity):
    one MUMPS LU factorisation, or a Krylov method when :func:`use_iterative` says so
    (:func:`krylov_fieldsplit` for Taylor-Hood, :func:`krylov_pmg` for P2, :func:`krylov_amg`
    for P1).

    ``A``: the PETSc matrix the Newton loop assembles (its near-nullspace is set here on the
    P1 path); ``prefix``: the solve's options prefix (this KSP's is ``prefix + "inner_"``).
    """

    def __init__(self, s: ContactSetup, A: Any, prefix: str) -> None:
        PETSc = s.m["PETSc"]
        self.ksp = PETSc.KSP().create(s.comm)
        self.ksp.setOptionsPrefix(f"{prefix}inner_")
        self.element = s.element
        self.iterative = use_iterative(s)
        self.iterations = 0  # Krylov iterations over all solves
        self.multigrid: PMultigrid | None = None
        self.keep: list = []  # PETSc objects of the preconditioner, destroyed with the solver
        self.option_keys: list[str] = []  # its entries in the PETSc options database, likewise
        self._configured = False
        if not self.iterative:
            self.ksp.setType("preonly")
            pc = self.ksp.getPC()
            pc.setType("lu")
            pc.setFactorSolverType("mumps")
            self.ksp.setFromOptions()
        elif s.element == "TH":
            self.multigrid, self.keep, self.option_keys = krylov_fieldsplit(self.ksp, s)
        elif s.element == "P2":
            self.multigrid, self.option_keys = krylov_pmg(self.ksp, s)
        else:
            self.option_keys = krylov_amg(self.ksp, A, s)
        self.ksp.setTolerances(rtol=INNER_RTOL, atol=0.0, max_it=INNER_MAX_IT)

    @property
    def method(self) -> str:
        """The Krylov method and preconditioner, as progress lines name them (``gmres+pmg``...)."""
        pc = {"TH": "fieldsplit", "P2": "pmg"}.get(self.element, "gamg")
        return f"{self.ksp.getType()}+{pc}"

    def set_operator(self, A: Any) -> None:
        """Factor (LU) or set up the preconditioner of the newly assembled ``A``."""
        if self.multigrid is not None:
            Ac = self.multigrid.update(A)
            if self._configured:
                self._multigrid_pc().getMGCoarseSolve().setOperators(Ac, Ac)
        self.ksp.setOperators(A)
        if self.multigrid is not None and not self._configured:
            if self.element == "TH":
                self.ksp.getPC().setUp()  # makes the split's KSPs
            self.multigrid.configure(self._multigrid_pc())
            self._configured = True
        self.ksp.setUp()

    def _multigrid_pc(self) -> Any:
        pc = self.ksp.getPC()
        return pc.getFieldSplitSubKSP()[0].getPC() if self.element == "TH" else pc

    def solve(self, b: Any, x: Any, rtol: float = INNER_RTOL, guess: bool = False) -> int:
        """x = A^-1 b; on the Krylov path to ``rtol`` of b's norm, from ``x`` when ``guess``. Returns
        the Krylov iterations (0 on the LU path). Raises :class:`FEConvergenceError` naming the
        Krylov method when the solve does not converge in :data:`INNER_MAX_IT` iterations."""
        if not self.iterative:
            self.ksp.solve(b, x)
            return 0
        self.ksp.setTolerances(rtol=rtol)
        self.ksp.setInitialGuessNonzero(guess)
        self.ksp.solve(b, x)
        its = self.ksp.getIterationNumber()
        self.iterations += its
        if self.ksp.getConvergedReason() <= 0:
            raise FEConvergenceError(
                f"the inner Krylov solve ({self.method}) did not converge",
                reason=str(self.ksp.getConvergedReason()), residual_norm=self.ksp.getResidualNorm(),
                iterations=its)
        return its

    def precondition(self, b: Any, x: Any) -> None:
        """x = M^-1 b, one application of the preconditioner (the LU: the exact solve)."""
        if self.iterative:
            self.ksp.getPC().apply(b, x)
        else:
            self.ksp.solve(b, x)

    def destroy(self) -> None:
        """Destroy the KSP and the preconditioner's objects and remove its options."""
        from petsc4py import PETSc

        self.ksp.destroy()
        for obj in self.keep:
            obj.destroy()
        if self.multigrid is not None:
            self.multigrid.destroy()
        db = PETSc.Options()
        for key in self.option_keys:
            del db[key]
