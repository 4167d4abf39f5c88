"""Hertz line contact: rigid cylinder (R = 20 mm) on a thick elastic block bonded to a rigid base.

Plane strain by a one-element-thick slice with zero normal displacement on both faces; half model
(symmetry x = 0). Block 20 mm wide (half) and 20 mm thick = 20 a, a = 1 mm: the half-space
closed form applies to well within the tolerances. Load per length P' = pi a^2 E* / (4 R).
Half-width from the FE contact area (indicator at quadrature points) / slice thickness.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import (  # noqa: E402
    HERTZ_BLOCK,
    HERTZ_R,
    hertz_mesh,
    hertz_problem,
    hertz_reference,
    report,
    triangulated_cylinder,
)

from fem_reference import solve_contact  # noqa: E402

pytestmark = pytest.mark.fe


def _hertz_errors(r, hc):
    ref = hertz_reference()
    a_fe = r.contact_area_mm2 / hc
    return (r.peak_pressure_mpa / ref.peak_pressure_mpa - 1.0, a_fe / ref.half_width_mm - 1.0,
            a_fe)


@pytest.mark.parametrize("hc, far, tol", [(0.25, 2.5, 0.03), (0.05, 2.0, 0.02)],
                         ids=["coarse", "fine"])
def test_hertz_peak_pressure_and_half_width(comm, hc, far, tol):
    """Hertz line contact, P2: p0 = 2P'/(pi a) and a = sqrt(4P'R/(pi E*)). Coarse mesh (contact
    element size a/4): within 3 %; finest test mesh (a/20 near the contact, 2 mm far): 2 %."""
    r = solve_contact(hertz_problem(hertz_mesh(comm, hc, size_far=far), hc))
    ep, ea, a_fe = _hertz_errors(r, hc)
    ref = hertz_reference()
    report(f"Hertz P2 hc={hc}", p0_fe=r.peak_pressure_mpa, p0=ref.peak_pressure_mpa, err_p0=ep,
           a_fe=a_fe, a=ref.half_width_mm, err_a=ea, n_dofs=r.n_dofs, newton=r.newton_iterations,
           wall_s=r.wall_time_s, rel_force_residual=r.relative_force_residual)
    assert abs(ep) < tol
    assert abs(ea) < tol
    assert r.relative_force_residual < 1e-6
    # nodal pressure (lumped projection) follows p0 sqrt(1 - x^2/a^2) inside 0.7 a, within
    # 2 tol of p0 (the projection smooths the steep flank near the edge on coarse meshes)
    x = r.contact_points_mm
    m = np.isclose(x[:, 1], 0.0) & (x[:, 0] < 0.7 * ref.half_width_mm)
    prof = np.abs(r.contact_pressure_mpa[m] - ref.pressure_mpa(x[m, 0])) / ref.peak_pressure_mpa
    print(f"[fe]   max profile deviation inside 0.7 a: {prof.max():.4f} p0 ({m.sum()} nodes)")
    assert prof.max() < 2 * tol


def test_triangulated_cylinder_matches_analytic_cylinder(comm):
    """RigidSurface (cylinder patch, 0.05 degree facets, nearest-triangle gap interpolated at the
    P2 dofs) reproduces the analytic RigidCylinder within 0.5 % (peak, displacement)."""
    hc = 0.2
    msh = hertz_mesh(comm, hc)
    exact = solve_contact(hertz_problem(msh, hc))
    surf = triangulated_cylinder(HERTZ_R, (0.0, 0.0, HERTZ_BLOCK + HERTZ_R), (-1.0, 1.0), 12.0,
                                 n_theta=480)
    tri = solve_contact(hertz_problem(msh, hc, obstacle=surf))
    report("Hertz triangulated vs analytic cylinder", p0_tri=tri.peak_pressure_mpa,
           p0_exact=exact.peak_pressure_mpa, d_tri=tri.bone_displacement_mm[2],
           d_exact=exact.bone_displacement_mm[2])
    assert tri.peak_pressure_mpa == pytest.approx(exact.peak_pressure_mpa, rel=5e-3)
    assert tri.bone_displacement_mm[2] == pytest.approx(exact.bone_displacement_mm[2], rel=5e-3)
    assert tri.contact_area_mm2 == pytest.approx(exact.contact_area_mm2, rel=0.02)
