"""Nearly incompressible cartilage (nu = 0.499): P1 locks, Taylor-Hood does not.

Unconfined compression of a bonded slab (10 x 10 x 2 mm, quarter model with two symmetry planes,
free lateral faces) pressed against a frictionless rigid plane: the bulging deformation that
locks P1 tetrahedra. Reference: P2 on a mesh refined by 2.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import report  # noqa: E402

from fem_reference import FEContactProblem, RigidPlane, Roller, solve_contact  # noqa: E402
from fem_reference import meshes  # noqa: E402

pytestmark = pytest.mark.fe

NU = 0.499


def _solve(comm, element, n):
    msh = meshes.box_slab(comm, 5.0, 5.0, 2.0, (n, n, max(2, int(0.8 * n))), confined=False,
                          quarter=True)
    prob = FEContactProblem(mesh=msh, youngs_modulus_mpa=10.35, poissons_ratio=NU,
                            obstacle=RigidPlane((0, 0, 2.0), (0, 0, -1.0)),
                            force_n=(0, 0, 10.0), element=element,
                            rollers=(Roller(4, "x"), Roller(5, "y")))
    return solve_contact(prob)


def test_taylor_hood_matches_p2_refinement_and_p1_locks(comm):
    """Invariant: locking-free elements agree (TH on mesh h within 2 % of P2 on mesh h/2) while
    P1 on mesh h underestimates the displacement by more than 25 %."""
    th = _solve(comm, "TH", 5)
    p2 = _solve(comm, "P2", 10)
    p1 = _solve(comm, "P1", 5)
    d_th, d_p2, d_p1 = (r.bone_displacement_mm[2] for r in (th, p2, p1))
    report("nu=0.499", d_TH_h=d_th, d_P2_h2=d_p2, d_P1_h=d_p1, TH_vs_P2=d_th / d_p2 - 1,
           P1_vs_P2=d_p1 / d_p2 - 1, peak_TH=th.peak_pressure_mpa, peak_P2=p2.peak_pressure_mpa,
           dofs_TH=th.n_dofs, dofs_P2=p2.n_dofs, wall_TH=th.wall_time_s, wall_P2=p2.wall_time_s)
    assert th.element == "TH" and p1.element == "P1"
    assert d_th == pytest.approx(d_p2, rel=0.02)
    assert th.peak_pressure_mpa == pytest.approx(p2.peak_pressure_mpa, rel=0.03)
    assert d_p1 < 0.75 * d_p2
    assert any("lock" in w for w in p1.warnings)
    for r in (th, p2, p1):
        assert r.relative_force_residual < 1e-6


def test_auto_element_is_taylor_hood_at_nu_0499(comm):
    """element='auto' picks Taylor-Hood for nu >= 0.49."""
    msh = meshes.box_slab(comm, 5.0, 5.0, 2.0, (2, 2, 2), confined=False, quarter=True)
    prob = FEContactProblem(mesh=msh, youngs_modulus_mpa=10.35, poissons_ratio=NU,
                            obstacle=RigidPlane((0, 0, 2.0), (0, 0, -1.0)), force_n=(0, 0, 10.0),
                            rollers=(Roller(4, "x"), Roller(5, "y")))
    assert solve_contact(prob).element == "TH"


def _cylinder_on_th_slab(comm, linear_solver):
    """Taylor-Hood slab (4 x 4 x 1 mm, free sides, 4.6k DOFs) under a rigid cylinder at nu = 0.499."""
    from fem_reference import RigidCylinder, SolverOptions

    msh = meshes.box_slab(comm, 4.0, 4.0, 1.0, (8, 8, 2), confined=False)
    return FEContactProblem(mesh=msh, youngs_modulus_mpa=10.35, poissons_ratio=NU,
                            obstacle=RigidCylinder((0, 0, 6.0), (0, 1.0, 0), 5.0), force_n=(0, 0, 5.0),
                            element="TH", solver=SolverOptions(linear_solver=linear_solver))


def test_taylor_hood_field_split_gives_the_lu_solution(comm):
    """The Krylov path for Taylor-Hood (GMRES + Schur-complement field split: GAMG with the
    rigid-body near-nullspace on u, the pressure mass matrix scaled by -(1/mu + 1/lambda) on p;
    docs/method.md, section 6) converges to the LU's contact solution: same bone displacement,
    peak pressure and contact area.

    Tolerance 2e-3 = 2 x condition x 1e-10: both Newton runs stop at 1e-10 of their first residual
    (each inner solve is exact to INNER_RTOL = 1e-10, so Newton reaches that stop), which puts each
    within condition x 1e-10 of the discrete solution relative to its starting error, the two
    within twice that; the 2-norm condition number of the last Jacobian here is 9.3e6 (scipy
    svds). Iterations: at most 80 per inner solve (measured 37 on average, 47 at most; the limit
    leaves room for another PETSc build's aggregation without admitting a preconditioner that
    does not see the saddle point, which does not converge at all, test below)."""
    direct = solve_contact(_cylinder_on_th_slab(comm, "direct"))
    krylov = solve_contact(_cylinder_on_th_slab(comm, "iterative"))
    solves = 2 * krylov.newton_iterations  # k + 1 inner solves per Newton step, k = 1 free translation
    report("TH field split vs LU", newton=krylov.newton_iterations, krylov=krylov.krylov_iterations,
           per_solve=krylov.krylov_iterations / solves, d=krylov.bone_displacement_mm[2],
           d_lu=direct.bone_displacement_mm[2], wall=krylov.wall_time_s, wall_lu=direct.wall_time_s)
    assert (direct.linear_solver, krylov.linear_solver) == ("direct", "iterative")
    assert 0 < krylov.krylov_iterations <= 80 * solves
    assert krylov.relative_force_residual < 1e-6
    rtol = 2.0 * 9.3e6 * 1e-10
    np.testing.assert_allclose(krylov.bone_displacement_mm, direct.bone_displacement_mm, rtol=rtol, atol=1e-12)
    assert krylov.peak_pressure_mpa == pytest.approx(direct.peak_pressure_mpa, rel=rtol)
    assert krylov.contact_area_mm2 == pytest.approx(direct.contact_area_mm2, rel=rtol)


def test_plain_amg_on_the_taylor_hood_saddle_point_does_not_converge(comm, monkeypatch):
    """Why the field split: GMRES with GAMG on the whole (u, p) matrix, as the P1/P2 path does,
    breaks down on the same problem within the inner iteration limit (the pressure block is
    -M/lambda, nearly zero at nu = 0.499: aggregation smooths a saddle point as if it were
    elliptic). The solve ends with FEConvergenceError naming the Krylov method."""
    from fem_reference import FEConvergenceError
    from fem_reference import krylov

    def plain_amg(ksp, s):
        return None, [], krylov.set_inner_options(ksp, {"ksp_type": "gmres", "ksp_pc_side": "right",
                                                  "ksp_gmres_restart": str(krylov.GMRES_RESTART), "pc_type": "gamg"})

    monkeypatch.setattr(krylov, "krylov_fieldsplit", plain_amg)
    with pytest.raises(FEConvergenceError, match="inner Krylov solve"):
        solve_contact(_cylinder_on_th_slab(comm, "iterative"))


def _undrained_quarter_slab(comm, **kw):
    """The undrained Taylor-Hood quarter slab (4 x 4 x 1 mm, free sides, mu = 0.35 MPa,
    nu = 0.4999) under a rigid cylinder R = 10 mm pressed by 0.1 N."""
    from fem_reference import RigidCylinder

    msh = meshes.box_slab(comm, 4.0, 4.0, 1.0, (8, 8, 2), confined=False, quarter=True)
    nu = 0.4999
    return FEContactProblem(mesh=msh, youngs_modulus_mpa=2.0 * 0.35 * (1.0 + nu), poissons_ratio=nu,
                            obstacle=RigidCylinder((0.0, 0.0, 11.0), (0.0, 1.0, 0.0), 10.0),
                            force_n=(0.0, 0.0, 0.1), rollers=(Roller(4, "x"), Roller(5, "y")),
                            element="TH", **kw)


def test_a_start_touching_nowhere_approaches_and_finds_the_touching_starts_answer(comm):
    """Invariant: the answer does not depend on the start. The touching estimate's Winkler bed
    takes lambda + 2 mu, so at nu = 0.4999 the start penetrates 2.9e-5 mm, a strip of 0.02 mm
    under the cylinder's line that holds no quadrature point of the contact facets: no contact
    pressure and no contact stiffness, the Schur complement of the rigid translation is round-off
    of either sign (it was -6e-14 and Newton walked away from the obstacle). From there Newton
    approaches along the load and converges to the answer of a start that touches (0.01 mm
    beyond first touch).

    Tolerance 1e-7: both runs end with |F| below 1e-11 of the load (the direct path reaches
    round-off), within condition x 1e-11 of the discrete solution; the condition number of the
    Jacobian of this Taylor-Hood slab is of the order of 1e7 (9.3e6 on the full slab above).
    Measured: the two agree to 2e-16."""
    from fem_reference.progress import SolveProgress

    lines: list[str] = []
    untouching = solve_contact(_undrained_quarter_slab(comm), comm, progress=SolveProgress(lines.append))
    touching = solve_contact(_undrained_quarter_slab(comm, initial_penetration_mm=0.01), comm)
    report("untouching start", newton=untouching.newton_iterations, d=untouching.bone_displacement_mm[2],
           newton_touching=touching.newton_iterations, d_touching=touching.bone_displacement_mm[2])
    if comm.rank == 0:
        assert ", 0 contact nodes" in lines[0]  # Newton 0: the start touches nowhere
    for r in (untouching, touching):
        assert r.relative_force_residual < 1e-6
    np.testing.assert_allclose(untouching.bone_displacement_mm, touching.bone_displacement_mm, rtol=1e-7)
    assert untouching.peak_pressure_mpa == pytest.approx(touching.peak_pressure_mpa, rel=1e-7)
    assert untouching.contact_area_mm2 == pytest.approx(touching.contact_area_mm2, rel=1e-7)
