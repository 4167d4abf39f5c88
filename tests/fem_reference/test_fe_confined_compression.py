"""Confined compression of a flat slab (closed form p = E' d / h), force-controlled."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import MATERIAL, plane_as_surface, report  # noqa: E402

from fem_reference import FEContactProblem, RigidPlane, Roller, solve_contact  # noqa: E402
from fem_reference import closed_forms as cf  # noqa: E402
from fem_reference import meshes  # noqa: E402

pytestmark = pytest.mark.fe

LX, LY, H = 10.0, 8.0, 2.0
LOAD = 120.0  # N -> p = LOAD / (LX * LY) = 1.5 MPa


@pytest.fixture(scope="module")
def slab(comm):
    return meshes.box_slab(comm, LX, LY, H, (5, 4, 2), confined=True)


def _problem(slab, element, obstacle=None):
    return FEContactProblem(
        mesh=slab, element=element, force_n=(0.0, 0.0, LOAD),
        obstacle=obstacle or RigidPlane((0.0, 0.0, H), (0.0, 0.0, -1.0)),
        rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL)


@pytest.mark.parametrize("element", ["P1", "P2", "TH"])
def test_confined_compression_matches_e_prime_d_over_h(slab, element):
    """Closed form: p = E' d / h (lateral faces on rollers). Pressure away from the edges within
    1 %, bone displacement d = p h / E' within 1 %, force balance 1e-6."""
    r = solve_contact(_problem(slab, element))
    p_exact = LOAD / (LX * LY)
    d_exact = cf.confined_compression_displacement(MATERIAL["youngs_modulus_mpa"],
                                                   MATERIAL["poissons_ratio"], H, p_exact)
    d = r.bone_displacement_mm[2]
    x = r.contact_points_mm
    inner = ((x[:, 0] > 0.2 * LX) & (x[:, 0] < 0.8 * LX) & (x[:, 1] > 0.2 * LY)
             & (x[:, 1] < 0.8 * LY))
    p_closed = cf.confined_compression_pressure(MATERIAL["youngs_modulus_mpa"],
                                                MATERIAL["poissons_ratio"], H, d)
    err_p = float(np.max(np.abs(r.contact_pressure_mpa[inner] / p_closed - 1.0)))
    report(f"confined compression {element}", d_fe=d, d_exact=d_exact,
           max_rel_err_p=err_p, area=r.contact_area_mm2,
           rel_force_residual=r.relative_force_residual,
           n_dofs=r.n_dofs, newton=r.newton_iterations, wall_s=r.wall_time_s)
    assert r.converged_reason.startswith("CONVERGED")
    assert inner.sum() >= 4
    assert err_p < 0.01
    assert d == pytest.approx(d_exact, rel=0.01)
    assert r.peak_pressure_mpa == pytest.approx(p_exact, rel=0.01)
    assert r.contact_area_mm2 == pytest.approx(LX * LY, rel=1e-9)
    assert r.relative_force_residual < 1e-6
    assert np.allclose(r.bone_displacement_mm[:2], 0.0)
    assert r.element == element


def test_triangulated_plane_obstacle_gives_the_same_answer(slab):
    """RigidSurface (two triangles, nearest-triangle gap) reproduces the analytic RigidPlane."""
    a = solve_contact(_problem(slab, "P1"))
    b = solve_contact(_problem(slab, "P1", plane_as_surface((0, 0, H), (0, 0, -1))))
    assert b.bone_displacement_mm[2] == pytest.approx(a.bone_displacement_mm[2], rel=1e-9)
    assert np.allclose(b.contact_pressure_mpa, a.contact_pressure_mpa, rtol=1e-8)


def test_mesh_callable_may_return_tags_in_either_order(slab):
    """A mesh source may be a callable returning (mesh, cell_tags, facet_tags), as
    geometries.fe_solids.FESolid.to_dolfinx does."""
    import numpy as np
    from dolfinx.mesh import meshtags

    m = slab.mesh
    ncells = m.topology.index_map(3).size_local + m.topology.index_map(3).num_ghosts
    cells = meshtags(m, 3, np.arange(ncells, dtype=np.int32), np.full(ncells, 10, dtype=np.int32))
    a = solve_contact(_problem(slab, "P1"))
    prob = _problem(slab, "P1")
    prob.mesh = lambda comm: (m, cells, slab.facet_tags)
    b = solve_contact(prob)
    assert b.bone_displacement_mm[2] == pytest.approx(a.bone_displacement_mm[2], rel=1e-12)
