"""Team reference: rigid cylinder R = 20 mm with a bonded 2 mm layer (E = 10.35 MPa,
nu = 0.42) on a rigid plane, 30 mm long. Quarter model (symmetry planes x = 0 and mid-length).

Reference (finer meshes, computed earlier on this machine): 333 N -> bone displacement
0.2599 mm, peak pressure 2.545 MPa at mid-length, contact area 193 +- 2 mm^2;
4190 N -> 1.438 mm, 15.17 MPa, 451-453 mm^2.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import MATERIAL, report  # noqa: E402

from fem_reference import FEContactProblem, RigidPlane, Roller, solve_contact  # noqa: E402
from fem_reference import meshes  # noqa: E402

pytestmark = pytest.mark.fe


def _solve(comm, load, **mesh_kw):
    msh = meshes.cylinder_layer_quarter(comm, bone_radius=20.0, thickness=2.0, length=30.0,
                                        **mesh_kw)
    prob = FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 0), (0, 0, 1.0)),
                            force_n=(0, 0, -load / 4.0), element="P2",
                            rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL)
    return solve_contact(prob)


def _check(r, load, d_ref, p_ref, area_ref, tol_d, tol_p, tol_a):
    d = -r.bone_displacement_mm[2]
    area = 4.0 * r.contact_area_mm2
    x = r.contact_points_mm
    mid = np.isclose(x[:, 0], 0.0) & (x[:, 1] > 12.0)  # bottom line near mid-length
    report(f"cylinder layer {load:g} N", disp=d, disp_ref=d_ref, err_d=d / d_ref - 1,
           peak=r.peak_pressure_mpa, peak_ref=p_ref, err_p=r.peak_pressure_mpa / p_ref - 1,
           area=area, area_ref=area_ref, err_a=area / area_ref - 1, n_dofs=r.n_dofs,
           newton=r.newton_iterations, wall_s=r.wall_time_s, strain=r.max_nominal_strain)
    assert d == pytest.approx(d_ref, rel=tol_d)
    assert r.peak_pressure_mpa == pytest.approx(p_ref, rel=tol_p)
    assert area == pytest.approx(area_ref, rel=tol_a)
    assert r.contact_pressure_mpa[mid].max() == pytest.approx(r.peak_pressure_mpa, rel=0.01)
    assert r.relative_force_residual < 1e-6
    assert any("strain" in w for w in r.warnings)  # 13 % nominal compression at 333 N


def test_cylinder_layer_333N_coarse(comm):
    """Coarse P2 (2 elements through the layer): within 2 % of 0.2599 mm and 2.545 MPa, area
    within 3 % of 193 mm^2."""
    r = _solve(comm, 333.0, n_radial=2, n_arc=20, arc_progression=1.08, n_length=15)
    _check(r, 333.0, 0.2599, 2.545, 193.0, 0.02, 0.02, 0.03)


@pytest.mark.slow
def test_cylinder_layer_4190N(comm):
    """Toe-off load (small-strain model far outside its range: the layer is compressed by 70 %):
    within 1 % of 1.438 mm and 15.17 MPa, area within 2 % of 452 mm^2."""
    r = _solve(comm, 4190.0, n_radial=4, n_arc=40, arc_progression=1.05, n_length=30)
    _check(r, 4190.0, 1.438, 15.17, 452.0, 0.01, 0.01, 0.02)
