"""Force balance (integrated contact pressure = applied load) and solver failure reporting."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import (  # noqa: E402
    HERTZ_BLOCK,
    HERTZ_R,
    MATERIAL,
    hertz_mesh,
    hertz_problem,
    hertz_reference,
    report,
)

from fem_reference import (  # noqa: E402
    FEContactProblem,
    FEConvergenceError,
    NitscheParameters,
    RigidCylinder,
    RigidPlane,
    Roller,
    SolverOptions,
    solve_contact,
)
from fem_reference import meshes  # noqa: E402

pytestmark = pytest.mark.fe


@pytest.fixture(scope="module")
def full_block(comm):
    """Whole Hertz block (no x symmetry), so the bone may translate sideways."""
    return meshes.hertz_block(comm, width=10.0, height=10.0, slice_thickness=0.2,
                              size_contact=0.2, size_far=2.0, fine_radius=2.0, coarse_radius=8.0,
                              half=False)


@pytest.mark.parametrize("element, nitsche", [
    ("P1", NitscheParameters()), ("P2", NitscheParameters()), ("TH", NitscheParameters()),
    ("P2", NitscheParameters(theta=1.0, gamma0=10.0)), ("P2", NitscheParameters(theta=0.0)),
])
def test_force_balance_hertz(comm, element, nitsche):
    """Invariant: the integrated Nitsche pressure force equals the applied load to 1e-6
    (relative) along the free direction for every element and Nitsche variant. The half model's
    x-component (the cylinder normal tilts away from the symmetry plane) is carried by the
    symmetry roller and reported as constraint force."""
    hc = 0.25
    r = solve_contact(hertz_problem(hertz_mesh(comm, hc, size_far=2.5), hc, element=element,
                                    nitsche=nitsche))
    report(f"force balance {element} theta={nitsche.theta}", force=r.contact_force_n[2],
           load=r.applied_force_n[2], rel_residual=r.relative_force_residual,
           newton=r.newton_iterations, reason=r.converged_reason)
    assert r.relative_force_residual < 1e-6
    assert abs(r.contact_force_n[1]) < 1e-12
    assert r.contact_force_n[0] < 0.0  # pressure pushes the half block towards -x
    assert np.allclose(r.constraint_force_n, [r.contact_force_n[0], 0, 0], atol=1e-12)
    assert r.converged_reason.startswith("CONVERGED")
    assert r.peak_pressure_mpa == pytest.approx(hertz_reference().peak_pressure_mpa, rel=0.05)


def test_two_free_translations_balance_a_tilted_load(comm, full_block):
    """Invariant: with x and z free, a load tilted by 0.1 rad-ish is carried entirely by the
    contact (both components to 1e-6): the bone slides until the cylinder normal aligns with
    the load, x ~ R * Px / |P|."""
    pz = hertz_reference().load_per_length_n_per_mm * 0.2
    load = (0.1 * pz, 0.0, pz)
    prob = FEContactProblem(mesh=full_block, force_n=load, free_dofs=("x", "z"),
                            obstacle=RigidCylinder((0, 0, 10.0 + HERTZ_R), (0, 1, 0), HERTZ_R),
                            rollers=(Roller(5, "y"),), element="P2", **MATERIAL)
    r = solve_contact(prob)
    slide = HERTZ_R * 0.1 / np.sqrt(1.01)
    report("tilted load, free x z", disp=list(np.round(r.bone_displacement_mm, 5)),
           force=list(r.contact_force_n), rel_residual=r.relative_force_residual,
           newton=r.newton_iterations)
    assert np.allclose(r.contact_force_n, load, rtol=0, atol=1e-6 * np.linalg.norm(load))
    assert np.allclose(r.constraint_force_n, 0.0, atol=1e-6 * np.linalg.norm(load))
    assert r.bone_displacement_mm[0] == pytest.approx(slide, rel=0.05)
    # only the load direction free: the perpendicular part goes to the fixed translations
    fixed = solve_contact(FEContactProblem(
        mesh=full_block, force_n=load, obstacle=prob.obstacle, rollers=prob.rollers,
        element="P2", **MATERIAL))
    d = fixed.free_directions[0]
    assert d @ fixed.contact_force_n == pytest.approx(np.linalg.norm(load), rel=1e-6)
    assert np.allclose(fixed.contact_force_n - fixed.constraint_force_n, load, atol=1e-9)


def test_non_convergence_raises_with_reason_and_residual(comm):
    """A Newton that stops early raises FEConvergenceError naming the SNES reason."""
    hc = 0.25
    prob = hertz_problem(hertz_mesh(comm, hc, size_far=2.5), hc,
                         solver=SolverOptions(max_iterations=1))
    with pytest.raises(FEConvergenceError) as info:
        solve_contact(prob)
    assert info.value.reason == "DIVERGED_MAX_IT"
    assert np.isfinite(info.value.residual_norm) and info.value.residual_norm > 0
    assert "DIVERGED_MAX_IT" in str(info.value)


def test_tangential_free_translation_is_reported(comm, full_block):
    """Frictionless contact on a plane cannot hold a free sideways translation: clear error."""
    prob = FEContactProblem(mesh=full_block, force_n=(0, 0, 0.1), free_dofs=("x", "z"),
                            obstacle=RigidPlane((0, 0, 10.0), (0, 0, -1.0)),
                            rollers=(Roller(5, "y"),), element="P1", **MATERIAL)
    with pytest.raises(FEConvergenceError, match="tangent"):
        solve_contact(prob)


def test_large_strain_warning(comm):
    """Nominal strain above 10 % is flagged (small-strain model)."""
    msh = meshes.box_slab(comm, 4.0, 4.0, 1.0, (2, 2, 1))
    prob = FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 1.0), (0, 0, -1.0)),
                            force_n=(0, 0, 16 * 0.15 * 26.4), element="P1",
                            rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL)
    r = solve_contact(prob)
    assert r.max_nominal_strain == pytest.approx(0.15, rel=0.01)
    assert any("strain" in w for w in r.warnings)


def test_summary_is_json_ready(comm):
    """The result summary has the docs/result-format.md keys that apply, as plain Python types."""
    import json

    msh = meshes.box_slab(comm, 4.0, 4.0, 1.0, (2, 2, 1))
    prob = FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 1.0), (0, 0, -1.0)),
                            force_n=(0, 0, 1.0), element="P1",
                            rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL)
    s = solve_contact(prob).summary()
    json.dumps(s)
    for key in ("n_dofs", "wall_time_s", "peak_pressure_mpa", "max_contact_area_mm2",
                "final_displacement_mm", "max_force_residual_n", "warnings"):
        assert key in s
    assert HERTZ_BLOCK > 0


@pytest.mark.parametrize("element, nitsche, condition", [
    ("P2", NitscheParameters(), 5.4e5),
    pytest.param("P1", NitscheParameters(theta=1.0, gamma0=10.0), 1.7e4, marks=pytest.mark.slow),
])
def test_krylov_amg_inner_solve_gives_the_direct_solution(comm, element, nitsche, condition):
    """The iterative inner solve (right-preconditioned GMRES, or CG for the symmetric theta = 1
    variant, with GAMG and the rigid-body near-nullspace; used when the LU would not fit in
    memory, fem_reference.sizing.direct_fits) converges to the LU solution: same bone
    displacement, peak pressure and contact area.

    Tolerance: both Newton runs stop at a residual of 1e-10 of their first (the inner solves are
    exact to INNER_RTOL = 1e-10 of their right-hand side, so Newton reaches that stop), which puts
    each within condition x 1e-10 of the discrete solution relative to its starting error (about
    the solution's size), and the two within twice that. ``condition``: the 2-norm condition number
    of the last Jacobian on this mesh (scipy svds, measured 5.4e5 for P2 and 1.7e4 for P1).

    Iterations: at most 100 per inner solve (k + 1 = 2 solves per Newton step); measured on the
    P2 mesh: 59 with these settings, 73 without the near-nullspace, 146 with PETSc's defaults
    (GMRES(30), unfiltered GAMG graph, 2 smoothing steps), the setting that did not converge on
    the 0.7 mm subject ankle."""
    hc = 0.25
    mesh = hertz_mesh(comm, hc, size_far=2.5)
    direct = solve_contact(hertz_problem(mesh, hc, element=element, nitsche=nitsche, solver=SolverOptions(linear_solver="direct")))
    krylov = solve_contact(hertz_problem(mesh, hc, element=element, nitsche=nitsche, solver=SolverOptions(linear_solver="iterative")))
    report(f"Krylov vs LU ({element})", newton=krylov.newton_iterations, krylov=krylov.krylov_iterations,
           per_solve=krylov.krylov_iterations / (2 * krylov.newton_iterations),
           d_diff=krylov.bone_displacement_mm[2] / direct.bone_displacement_mm[2] - 1)
    assert (direct.linear_solver, krylov.linear_solver) == ("direct", "iterative")
    assert (direct.krylov_iterations, 0 < krylov.krylov_iterations) == (0, True)
    assert krylov.krylov_iterations <= 100 * 2 * krylov.newton_iterations
    assert krylov.relative_force_residual < 1e-6
    rtol = 2.0 * condition * 1e-10
    np.testing.assert_allclose(krylov.bone_displacement_mm, direct.bone_displacement_mm, rtol=rtol, atol=1e-12)
    assert krylov.peak_pressure_mpa == pytest.approx(direct.peak_pressure_mpa, rel=rtol)
    assert krylov.contact_area_mm2 == pytest.approx(direct.contact_area_mm2, rel=rtol)
