"""Frictionless Nitsche contact between two elastic layers, each bonded to its rigid bone
(docs/method.md#two-deformable-layers).

One dolfinx mesh holds both layers (two disconnected cell regions) and one function space; F's
cells are tagged ``DeformableCounterpart.cell_tag``. F's bone is held fixed (u = 0 on its bonded
face), M's moves rigidly under force control as in the one-body solve
(:func:`fem_reference.contact.solve_contact`): its rigid modes are non-zero on M's cells only, so
they stay strain-free and testing with them still gives M's force balance.

The contact faces share one triangulation and the pairing is DOF to DOF, fixed in the reference
configuration (small sliding): a sparse 0/1 operator P maps each displacement DOF of F's contact
face onto the paired DOF of M's, ``w = P u`` (F's displacement carried to M's contact face, a
function of the collapsed displacement space W). With ``DeformableCounterpart.follow_slip`` a
node may instead face a point inside one of F's facets (P then holds that facet's Lagrange
weights) and :func:`fem_reference.contact.solve_contact` repeats the solve until that pairing
stops moving (:meth:`TwoBodySetup.moved_pairing`). The contact terms are the one-body Nitsche form
(biased: M's stress) with M's displacement u replaced by the relative one u - w, plus the virtual
work of the contact pressure on F, tested through W:

    F_u(u, w; v) = one-body form with u_n = -(u - w) . nu        (test v in V)
    F_w(u, w; z) = p(u, w) z . nu ds_M                            (test z in W)

nu = the interface's normal at the pair (out of F), gap = (Y - Z) . nu (:class:`DeformableCounterpart`).
Since w = P u, the residual and the Jacobian in V are

    R = F_u + P^T F_w,      J = J_uu + J_uw P + P^T J_wu + P^T J_ww P

assembled with PETSc's sparse products (the pairing and so the sparsity are fixed: the products
and the sum keep one pattern, computed once). The bordered Newton system, its inner solve and the
result are the one-body solver's (:class:`TwoBodySystem` only assembles differently).

A Kelvin-Voigt time step (:mod:`fem_reference.viscoelastic`: both layers creep with one tau) is
the one-body one with the history taken relative to F's: the shifted gap c0 gap + (h - P h) . nu
(:meth:`TwoBodySetup.gap_history`), since the contact condition acts on u - w.

Heavy imports (dolfinx, PETSc, ufl) happen inside the functions (:mod:`fem_reference.fe_stack`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .contact import OBSTACLE_SOLVERS, BorderedSystem
from .contact_setup import ContactSetup
from .problem import DeformableCounterpart, FEContactProblem


#: The pairing follows the slip (:meth:`TwoBodySetup.moved_pairing`) until a pass moves no paired
#: point by more than this fraction of the largest slip. Each pass shrank that move about 40-fold on
#: the cylindrical layer on a flat one (docs/method.md#two-deformable-layers), and the answer changed
#: below 1e-4 after the move fell under 5 % of the slip.
PAIRING_RTOL = 0.05


class TwoBodySetup(ContactSetup):
    """:class:`ContactSetup` for M's layer against F's deformable one in the same mesh.

    Adds to the one-body set-up: F's bonded face held (with M's bonded face, the conditions on
    u~), Lame's parameters per cell (DG0: M's and F's materials), rigid modes that vanish on F,
    the pairing operator ``P`` (PETSc, W x V), F's displacement at M's contact face ``w`` and the
    paired geometry (``offset`` Z - Y and the contact normal, functions of W on M's contact face)."""

    def __init__(self, problem: FEContactProblem, comm: Any, element: str) -> None:
        counterpart = problem.obstacle
        if not isinstance(counterpart, DeformableCounterpart):
            raise TypeError("TwoBodySetup needs a DeformableCounterpart obstacle")
        self.counterpart = counterpart
        self._relative_history: Any = None  # h - P h (gap_history), built on first use
        super().__init__(problem, comm, element)
        fem = self.m["fem"]
        if self.cell_tags is None:
            raise ValueError("two deformable layers need cell tags (F's cells tagged "
                             f"{counterpart.cell_tag})")
        self.fixed_cells = self.cell_tags.find(counterpart.cell_tag)
        self.fixed_contact_facets = self._facets(counterpart.contact_tag, "fixed contact")
        if self.element == "TH":
            self.W, (self.w_to_v,) = self.V.sub(0).collapse()
            self.w_to_v = np.asarray(self.w_to_v, dtype=np.int64)
        else:
            self.W = self.V
            imap = self.V.dofmap.index_map
            self.w_to_v = np.arange(3 * (imap.size_local + imap.num_ghosts), dtype=np.int64)
        self.w = fem.Function(self.W, name="fixed_displacement_at_mobile")
        self.offset = fem.Function(self.W)  # Z - Y on M's contact face
        self.contact_normal = fem.Function(self.W)  # nu at the pair, out of F
        self.P = self._pairing_operator()

    # ---- hooks of ContactSetup ----
    def _bonded_facets(self) -> np.ndarray:
        """M's bonded face (moves with the bone) and F's (held): u~ = 0 on both."""
        mobile = self._facets(self.problem.bonded_tag, "bonded")
        fixed = self._facets(self.counterpart.bonded_tag, "fixed bonded")
        return np.unique(np.concatenate([mobile, fixed])).astype(np.int32)

    def _material(self) -> tuple[Any, Any]:
        """Lame's parameters per cell: M's (the problem's) and F's (the counterpart's)."""
        fem = self.m["fem"]
        D = fem.functionspace(self.mesh, ("DG", 0))
        lam, mu = fem.Function(D, name="lambda"), fem.Function(D, name="mu")
        (lm, mm), (lf, mf) = self.problem.lame(), self.counterpart.lame()
        lam.x.array[:], mu.x.array[:] = lm, mm
        fixed = self.cell_tags.find(self.counterpart.cell_tag) if self.cell_tags is not None else []
        lam.x.array[fixed], mu.x.array[fixed] = lf, mf
        return lam, mu

    def rigid_modes(self) -> list:
        """M's bone's free translations and rotations, moving M's cells only (F's dofs zero)."""
        modes = super().rigid_modes()
        bs = self.V.dofmap.bs
        cells = self.V.dofmap.list[self.fixed_cells]
        fixed = (cells.reshape(-1, 1) * bs + np.arange(bs)).ravel()
        for e in modes:
            e.x.array[fixed] = 0.0
        return modes

    def relative_displacement(self, u: Any) -> Any:
        return u - self.w

    def gap_history(self) -> Any:
        """A Kelvin-Voigt step's history relative to F's: h - P h on M's contact face (h holds both
        layers' histories, and the contact condition acts on the relative displacement, so its
        shifted gap is c0 gap + (h - P h) . nu); a Function of h's space, or None."""
        h = self.problem.gap_history
        if h is not None and self._relative_history is None:
            fem = self.m["fem"]
            full = fem.Function(self.V)
            (full.sub(0) if self.element == "TH" else full).interpolate(h)
            paired = fem.Function(self.W)  # F's history at the points paired with M's contact face
            self.P.mult(full.x.petsc_vec, paired.x.petsc_vec)
            paired.x.scatter_forward()
            relative = fem.Function(h.function_space)
            relative.interpolate(paired)
            relative.x.array[:] = h.x.array - relative.x.array
            self._relative_history = relative
        return None if h is None else self._relative_history

    def _obstacle_ufl(self) -> tuple[Any, Any]:
        """gap = (Y - Z) . nu and nu, the unit contact normal at the pair (out of F)."""
        ufl = self.m["ufl"]
        nu = self.contact_normal / ufl.sqrt(ufl.dot(self.contact_normal, self.contact_normal))
        return -ufl.dot(self.offset, nu), nu

    # ---- the pairing ----
    def _v_global(self, local: np.ndarray) -> np.ndarray:
        """Global PETSc indices of V's local (unrolled) dofs."""
        bs = self.V.dofmap.index_map_bs
        return self.V.dofmap.index_map.local_to_global((local // bs).astype(np.int32)) * bs + local % bs

    def _pairing_operator(self) -> Any:
        """P (W x V): row (node i of M's contact face, component c) holds the weights of the same
        component of F's nodes at i's paired point (one 1 at its partner node, or after sliding the
        Lagrange weights of F's facet there). Sets ``offset`` and ``contact_normal`` on M's contact
        face. Parallel: F's contact nodes are gathered on every rank (a face, small beside the volume)."""
        fem, PETSc = self.m["fem"], self.m["PETSc"]
        W = self.W
        x = W.tabulate_dof_coordinates()
        imap = W.dofmap.index_map
        slave = fem.locate_dofs_topological(W, self.fdim, self.contact_facets)
        self.slave = slave = np.sort(slave[slave < imap.size_local])
        master = fem.locate_dofs_topological(W, self.fdim, self.fixed_contact_facets)
        master_v = self._v_global(self.w_to_v[(3 * master[:, None] + np.arange(3)).ravel()]).reshape(-1, 3)
        coords = np.concatenate(self.comm.allgather(x[master]))
        columns = np.concatenate(self.comm.allgather(master_v))
        y = x[slave]
        _, normal = self.counterpart.gap_and_normal(y)
        z = self.counterpart.facing_points(y)
        stencil, weights = self.counterpart.stencil(y, self.degree)
        k = weights.shape[1]
        used = weights != 0.0
        if used.any():
            if not len(coords):
                raise ValueError("no node on F's contact face")
            dist, j = cKDTree(coords).query(stencil[used])
            size = float(np.ptp(coords, axis=0).max())
            if float(dist.max()) > 1e-8 * size:
                raise ValueError(f"{int(np.sum(dist > 1e-8 * size))} paired points of F's contact face are not nodes "
                                 f"of the mesh (farthest {float(dist.max()):.3g} mm): the mesh does not match the pairing")
        else:
            j = np.zeros(0, dtype=np.int64)
        self.offset.x.array.reshape(-1, 3)[slave] = z - y
        self.contact_normal.x.array.reshape(-1, 3)[slave] = normal
        for f in (self.offset, self.contact_normal):
            f.x.scatter_forward()
        # CSR of the owned rows (3 per node of W, node by node): row (i, c) of a node of M's face
        # holds its stencil's weights at component c of F's nodes, other rows are empty
        n_rows = 3 * imap.size_local
        count = np.zeros(n_rows, dtype=np.int64)
        node_of = np.repeat(np.arange(len(slave)), k).reshape(-1, k)[used]
        rows = (3 * slave[node_of][:, None] + np.arange(3)).T  # (3, m): component-major
        np.add.at(count, rows.ravel(), 1)
        cols = np.concatenate([columns[j, c] for c in range(3)])
        order = np.lexsort((cols, rows.ravel()))  # by row, columns ascending within a row
        indptr = np.concatenate([[0], np.cumsum(count)]).astype(PETSc.IntType)
        cols = cols[order].astype(PETSc.IntType)
        vals = np.tile(weights[used], 3)[order]
        P = PETSc.Mat().createAIJ(((n_rows, PETSc.DECIDE), (self.n_owned, PETSc.DECIDE)), csr=(indptr, cols, vals), comm=self.comm)
        P.assemble()
        return P

    def moved_pairing(self, uh: Any) -> DeformableCounterpart | None:
        """The counterpart paired in the deformed configuration (:meth:`DeformableCounterpart.slid`
        by the relative tangential displacement (u - w) - ((u - w) . nu) nu of each node of M's
        contact face), or None when it would move no paired point by more than
        :data:`PAIRING_RTOL` of the largest slip (or the counterpart does not follow the slip)."""
        if not self.counterpart.follow_slip:
            return None
        y = self.W.tabulate_dof_coordinates()[self.slave]
        u = uh.x.array[self.w_to_v[(3 * self.slave[:, None] + np.arange(3)).ravel()]].reshape(-1, 3)
        relative = u - self.w.x.array.reshape(-1, 3)[self.slave]
        _, nu = self.counterpart.gap_and_normal(y)
        slip = relative - np.einsum("ij,ij->i", relative, nu)[:, None] * nu
        y, slip = (np.concatenate(self.comm.allgather(a)) for a in (y, slip))
        moved = self.counterpart.slid(y, slip)
        change = float(np.abs(moved.facing_points(y) - self.counterpart.facing_points(y)).max(initial=0.0))
        largest = float(np.abs(slip).max(initial=0.0))
        extent = float(np.ptp(y, axis=0).max()) if len(y) else 1.0
        # (a slip of round-off, as in confined compression, moves nothing: 1e-9 of the face's extent)
        return None if change <= max(PAIRING_RTOL * largest, 1e-9 * extent) else moved

    def update_counterpart(self, uh: Any) -> None:
        """w = P u: F's displacement at the paired points of M's contact face."""
        self.P.mult(uh.x.petsc_vec, self.w.x.petsc_vec)
        self.w.x.scatter_forward()


class TwoBodySystem(BorderedSystem):
    """The bordered Newton system of :mod:`fem_reference.contact` for two layers: the residual
    R = F_u + P^T F_w and the Jacobian J = J_uu + J_uw P + P^T J_wu + P^T J_ww P in one matrix of
    fixed sparsity; K = J E, G = J^T E, H = E^T J E from it (E: M's rigid modes). As in the
    one-body system, the bulk part of J_uu (both layers' elasticity, linear) is assembled once and
    each Newton step assembles the contact facets' terms alone."""

    @staticmethod
    def forms(s: ContactSetup, bulk: Any, contact: Any, uh: Any, E: list, pressure: Any, nu: Any) -> dict:
        """F_u = ``bulk`` + ``contact`` (the contact term holds u - w), F_w = p z . nu ds on M's
        contact face, and their derivatives in u and w: the bulk's (``bulk``) once, the contact
        terms' (``F``, ``Fw``, ``J..``) at each Newton step; ``touching``: :meth:`BorderedSystem.touching_form`."""
        fem, ufl = s.m["fem"], s.m["ufl"]
        z = ufl.TestFunction(s.W)
        Fw = pressure * ufl.dot(z, nu) * s.ds_c
        du, dw = ufl.TrialFunction(s.V), ufl.TrialFunction(s.W)
        return {"bulk": fem.form(ufl.derivative(bulk, uh, du)), "F": fem.form(contact), "Fw": fem.form(Fw),
                "Juu": fem.form(ufl.derivative(contact, uh, du)), "Juw": fem.form(ufl.derivative(contact, s.w, dw)),
                "Jwu": fem.form(ufl.derivative(Fw, uh, du)), "Jww": fem.form(ufl.derivative(Fw, s.w, dw)),
                "touching": BorderedSystem.touching_form(s, pressure)}

    def _create_matrix(self) -> Any:
        """The bulk matrix, the contact blocks, their products with P and A with the union of
        their sparsity patterns."""
        PETSc, fp = self.s.m["PETSc"], self.s.m["fem_petsc"]
        P = self.s.P
        self.A_bulk = fp.assemble_matrix(self.f["bulk"])
        self.A_bulk.assemble()
        # assembled once (explicit zeros included): a matrix assembled empty would lose its pattern
        self.blocks = {key: fp.assemble_matrix(self.f[key]) for key in ("Juu", "Juw", "Jwu", "Jww")}
        for mat in self.blocks.values():
            mat.assemble()
        b = self.blocks
        self.products = [b["Juw"].matMult(P), P.transposeMatMult(b["Jwu"]), b["Jww"].PtAP(P)]
        A = self.A_bulk.duplicate(copy=True)
        for C in (b["Juu"], *self.products):
            A.axpy(1.0, C, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        return A

    def set_state(self, X: Any) -> None:
        super().set_state(X)
        self.s.update_counterpart(self.uh)

    def _residual_vector(self) -> np.ndarray:
        PETSc, fp = self.s.m["PETSc"], self.s.m["fem_petsc"]
        fw = fp.assemble_vector(self.f["Fw"])
        fw.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.s.P.multTranspose(fw, self.zu)
        fw.destroy()
        coupling = np.array(self.zu.getArray(readonly=True))
        return super()._residual_vector() + coupling

    def _assemble_jacobian(self) -> None:
        PETSc, fp, s = self.s.m["PETSc"], self.s.m["fem_petsc"], self.s
        subset = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
        b, P = self.blocks, s.P
        for key, mat in b.items():
            mat.zeroEntries()
            fp.assemble_matrix(mat, self.f[key])
            mat.assemble()
        b["Juw"].matMult(P, result=self.products[0])
        P.transposeMatMult(b["Jwu"], result=self.products[1])
        b["Jww"].PtAP(P, result=self.products[2])
        A = self.A
        A.zeroEntries()
        for C in (self.A_bulk, b["Juu"], *self.products):
            A.axpy(1.0, C, structure=subset)
        self._borders()

    def release(self) -> None:
        super().release()
        for mat in (*self.blocks.values(), *self.products):
            mat.destroy()


OBSTACLE_SOLVERS[DeformableCounterpart] = (TwoBodySetup, TwoBodySystem)
