"""Nearly incompressible cartilage (nu = 0.499): P1 locks, Taylor-Hood does not.

Unconfined compression of a bonded slab (10 x 10 x 2 mm, quarter model with two symmetry planes,
free lateral faces) pressed against a frictionless rigid plane: the bulging deformation that
locks P1 tetrahedra. Reference: P2 on a mesh refined by 2.
"""

from __future__ import annotations

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
