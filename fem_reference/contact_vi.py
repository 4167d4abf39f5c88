"""Variational-inequality cross-check of the Nitsche contact solver (:mod:`fem_reference.contact`).

:func:`solve_contact_vi`: P1, a plane obstacle whose normal is a coordinate axis, one free
translation. Each inner solve is displacement-controlled with bounds on the contact-surface
dofs (PETSc ``vinewtonrsls``); a safeguarded secant on the translation meets the force. The tests
compare it with :func:`fem_reference.contact.solve_contact` on the same meshes.

Heavy imports (dolfinx, petsc4py, ufl) happen inside the function (:mod:`fem_reference.fe_stack`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .contact_setup import ContactSetup
from .fe_stack import fe_modules, options_prefix, snes_reason_name
from .problem import AREA_DEFINITION_VI, FEContactProblem, FEContactResult, FEConvergenceError, RigidPlane


def solve_contact_vi(problem: FEContactProblem, comm: Any = None, *, max_outer: int = 30,
                     keep_fields: bool = False) -> FEContactResult:
    """Cross-check: P1, plane obstacle whose normal is a coordinate axis, one free translation.

    Each inner solve is displacement-controlled (bonded face at t e) with bounds
    ``gap + u . nu >= 0`` on the contact-surface dofs, solved by PETSc ``vinewtonrsls``. The
    translation t is found by a safeguarded secant iteration on the bone reaction
    ``R(t) = e . (reaction of the bonded face)`` until ``R(t) = e . force_n`` (relative 1e-9).
    Contact pressure: nodal contact reaction divided by the lumped nodal area.
    ``problem.solver.petsc_options`` are added to the inner SNES options.
    """
    t_start = time.perf_counter()
    m = fe_modules()
    fem, ufl, PETSc, MPI = m["fem"], m["ufl"], m["PETSc"], m["MPI"]
    comm = MPI.COMM_WORLD if comm is None else comm
    obs = problem.obstacle
    if not isinstance(obs, RigidPlane) or obs.axis() is None:
        raise ValueError("the VI path needs a RigidPlane whose normal is a coordinate axis")
    if problem.gap_history is not None or problem.gap_scale != 1.0:
        raise ValueError("the VI path solves elastic problems only (no Kelvin-Voigt shifted gap)")
    element = problem.resolved_element() if problem.element != "auto" else "P1"
    if element != "P1":
        raise ValueError("the VI path supports P1 elements only")
    s = ContactSetup(problem, comm, "P1")
    if s.k != 1:
        raise ValueError("the VI path supports exactly one free translation")
    e = s.dirs[0]
    c = obs.axis()
    nu_c = float(np.sign(obs.normal[c]))
    target = float(e @ s.load)

    uh = fem.Function(s.V, name="displacement")
    v = ufl.TestFunction(s.V)
    F = ufl.inner(s.sigma(uh), s.eps(v)) * s.dx
    tval = fem.Constant(s.mesh, np.zeros(3))
    bcs = [fem.dirichletbc(tval, s.bc_bonded_dofs, s.V)] + s.bcs[1:]
    prefix = options_prefix("fevi")
    load_norm = float(np.linalg.norm(s.load))
    opts = {"snes_type": "vinewtonrsls", "snes_linesearch_type": "basic",
            "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps",
            "snes_rtol": 1e-12, "snes_atol": 1e-13 * load_norm, "snes_stol": 0.0,
            "snes_max_it": 50, "snes_divergence_tolerance": -1}
    opts.update(dict(problem.solver.petsc_options))  # the caller's extra SNES options, as for solve_contact
    nlp = m["fem_petsc"].NonlinearProblem(F, uh, bcs=bcs, petsc_options_prefix=prefix,
                                          petsc_options=opts)
    lb = nlp.x.duplicate()
    ub = nlp.x.duplicate()
    lb.set(PETSc.NINFINITY)
    ub.set(PETSc.INFINITY)
    nodes = fem.locate_dofs_topological(s.V, s.fdim, s.contact_facets)
    nloc_nodes = s.V.dofmap.index_map.size_local
    own_nodes = np.sort(nodes[nodes < nloc_nodes])
    pts = s.V.tabulate_dof_coordinates()[own_nodes]
    g, _ = obs.gap_and_normal(pts)
    idx = own_nodes * 3 + c
    with (lb if nu_c > 0 else ub) as bound:
        bound[idx] = -g if nu_c > 0 else g
    nlp.solver.setVariableBounds(lb, ub)

    a_vec = fem.form(F)
    b_idx, b_first = s.bcs[0].dof_indices()
    b_own = np.asarray(b_idx[:b_first])

    total_inner = 0

    def reaction(t: float) -> float:
        nonlocal total_inner
        tval.value[:] = t * e
        nlp.solve()
        reason = nlp.solver.getConvergedReason()
        total_inner += nlp.solver.getIterationNumber()
        if reason <= 0:
            raise FEConvergenceError(
                f"VI contact solve did not converge at translation {t:.6g} mm",
                reason=snes_reason_name(PETSc, reason),
                residual_norm=nlp.solver.getFunctionNorm(), iterations=total_inner)
        b = s.vector_owned(a_vec)
        return s.comm.allreduce(float(np.dot(b[b_own], e[b_own % 3])), op=MPI.SUM)

    t0, t_touch, pen = s.initial_translation()
    ta, fa = t_touch, 0.0
    tb = float(e @ t0)
    fb = reaction(tb)
    outer = 1
    lo, hi = (ta, fa), None  # bracket: f(lo) < target <= f(hi)
    tol = 1e-9 * abs(target)
    while abs(fb - target) > tol:
        if outer >= max_outer:
            raise FEConvergenceError("VI secant on the translation did not converge",
                                     reason="DIVERGED_MAX_IT", residual_norm=abs(fb - target),
                                     iterations=total_inner)
        if fb < target:
            lo = (tb, fb)
        else:
            hi = (tb, fb)
        slope = (fb - fa) / (tb - ta) if tb != ta else 0.0
        tn = tb + (target - fb) / slope if slope > 0 else tb + 2.0 * (tb - ta)
        if hi is not None and not (lo[0] < tn < hi[0]):  # keep inside the bracket
            tn = lo[0] + (target - lo[1]) * (hi[0] - lo[0]) / (hi[1] - lo[1])
        ta, fa = tb, fb
        tb = tn
        fb = reaction(tb)
        outer += 1

    # nodal contact reactions -> pressure
    b = s.vector_owned(a_vec)
    lam_n = b[idx] * nu_c  # contact force on the body along nu (>= 0)
    mass = s.vector_owned(fem.form(v[c] * s.ds_c))[idx]  # lumped nodal areas, same layout
    pnod = np.where(mass > 0, lam_n / np.where(mass > 0, mass, 1.0), 0.0)
    pnod = np.where(pnod > 0, pnod, 0.0)
    fc_local = -nu_c * float(np.sum(lam_n))
    contact_force = np.zeros(3)
    contact_force[c] = s.comm.allreduce(fc_local, op=MPI.SUM)
    p_all = s.gather(pnod)
    x_all = s.gather(pts)
    peak = float(p_all.max()) if len(p_all) else 0.0
    active = pnod > 1e-8 * max(peak, 1e-300)
    area = s.comm.allreduce(float(np.sum(mass[active])), op=MPI.SUM)
    fields = {"mesh": s.mesh, "solution": uh, "setup": s} if keep_fields else None
    return s.result(method="vi", area_definition=AREA_DEFINITION_VI, translation_mm=tb * e, points_mm=x_all,
                    pressure_mpa=p_all, peak_pressure_mpa=peak,
                    mean_pressure_mpa=abs(contact_force[c]) / area if area > 0 else 0.0,
                    contact_area_mm2=area, contact_force_n=contact_force, displacement=uh,
                    n_dofs=s.n_global, newton_iterations=total_inner, converged_reason="CONVERGED_SECANT",
                    started=t_start, warnings=[], fields=fields, outer_iterations=outer)
