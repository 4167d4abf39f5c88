"""Mesh convergence of the FE contact model on the Hertz case (three meshes, ratio 2).

Every length of the mesh (contact size, far size, slice) is halved between meshes, so observed
orders are meaningful. Orders: Richardson from the three solutions for the bone displacement
(no closed form: the Hertz rigid approach depends on the domain), and from the errors against the
Hertz peak pressure p0.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import hertz_mesh, hertz_problem, hertz_reference, report  # noqa: E402

from fem_reference import closed_forms as cf  # noqa: E402
from fem_reference import solve_contact  # noqa: E402

pytestmark = pytest.mark.fe


def _sweep(comm, element, sizes):
    rows = []
    for hc in sizes:
        r = solve_contact(hertz_problem(hertz_mesh(comm, hc), hc, element=element))
        rows.append((hc, r.bone_displacement_mm[2], r.peak_pressure_mpa, r.contact_area_mm2 / hc,
                     r.n_dofs, r.wall_time_s, r.newton_iterations))
        assert r.relative_force_residual < 1e-6
    return np.array(rows)


@pytest.mark.parametrize("element, sizes, min_order_d, min_order_p", [
    ("P2", (0.4, 0.2, 0.1), 1.5, 1.5),
    ("P1", (0.2, 0.1, 0.05), 1.0, 0.3),
])
def test_mesh_convergence_displacement_and_peak_pressure(comm, element, sizes, min_order_d,
                                                         min_order_p):
    """Observed orders on three meshes: displacement (Richardson) and peak pressure (against
    Hertz p0) converge; errors decrease monotonically on refinement."""
    ref = hertz_reference()
    rows = _sweep(comm, element, sizes)
    d, p0, a = rows[:, 1], rows[:, 2], rows[:, 3]
    err_p = p0 / ref.peak_pressure_mpa - 1.0
    err_a = a / ref.half_width_mm - 1.0
    order_d = cf.observed_order(d)
    orders_p = cf.observed_order_vs_exact(err_p)
    orders_a = cf.observed_order_vs_exact(err_a)
    for row, ep, ea in zip(rows, err_p, err_a):
        report(f"convergence {element} hc={row[0]}", disp=row[1], err_p0=ep, err_a=ea,
               n_dofs=int(row[4]), wall_s=row[5], newton=int(row[6]))
    report(f"observed orders {element}", disp_richardson=order_d,
           disp_extrapolated=cf.richardson_extrapolate(d),
           p0_vs_hertz=[round(float(v), 2) for v in orders_p],
           half_width_vs_hertz=[round(float(v), 2) for v in orders_a])
    assert order_d > min_order_d
    assert abs(d[2] - d[1]) < abs(d[1] - d[0])
    assert np.all(np.abs(err_p[1:]) < np.abs(err_p[:-1]))
    assert orders_p.mean() > min_order_p
    assert abs(err_p[-1]) < 0.01 and abs(err_a[-1]) < 0.02
