"""Nitsche vs PETSc variational inequality (vinewtonrsls) on the same P1 meshes.

Both apply where the obstacle is a plane with a coordinate-axis normal. Same force-controlled
load; the VI finds the translation by a secant on the bone reaction.
"""

from __future__ import annotations

import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import MATERIAL, report  # noqa: E402

from fem_reference import (  # noqa: E402
    FEContactProblem,
    RigidPlane,
    Roller,
    solve_contact,
    solve_contact_vi,
)
from fem_reference import meshes  # noqa: E402

pytestmark = pytest.mark.fe


def _both(prob):
    a, b = solve_contact(prob), solve_contact_vi(prob)
    for r in (a, b):
        assert r.relative_force_residual < 1e-6
    return a, b


def test_nitsche_and_vi_agree_bulging_slab(comm):
    """Invariant: bonded slab with free sides pressed on a plane (non-uniform pressure, full
    contact): bone displacement and peak pressure agree to 0.1 %."""
    msh = meshes.box_slab(comm, 10.0, 10.0, 2.0, (10, 10, 8), confined=False)
    prob = FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 2.0), (0, 0, -1.0)),
                            force_n=(0, 0, 100.0), element="P1", **MATERIAL)
    a, b = _both(prob)
    da, db = a.bone_displacement_mm[2], b.bone_displacement_mm[2]
    report("Nitsche vs VI, bulging slab P1", d_nitsche=da, d_vi=db, rel=da / db - 1,
           peak_nitsche=a.peak_pressure_mpa, peak_vi=b.peak_pressure_mpa,
           n_dofs=a.n_dofs, newton_nitsche=a.newton_iterations, inner_vi=b.newton_iterations,
           outer_vi=b.outer_iterations, wall_nitsche=a.wall_time_s, wall_vi=b.wall_time_s)
    assert da == pytest.approx(db, rel=1e-3)
    assert a.peak_pressure_mpa == pytest.approx(b.peak_pressure_mpa, rel=1e-3)
    assert a.contact_area_mm2 == pytest.approx(100.0, rel=1e-6)
    assert b.contact_area_mm2 == pytest.approx(100.0, rel=1e-6)


def test_nitsche_and_vi_agree_partial_contact_cylinder_layer(comm):
    """Invariant: cylinder with a bonded layer on a plane (partial contact, moving contact edge):
    bone displacement within 0.3 %, peak within 3 %, contact area within 6 % (the VI counts the
    whole lumped area of the last active node, see AREA_DEFINITION_VI) on a
    P1 mesh with 8 elements through the layer."""
    msh = meshes.cylinder_layer_quarter(comm, n_radial=8, n_arc=40, n_length=15)
    prob = FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 0), (0, 0, 1.0)),
                            force_n=(0, 0, -333.0 / 4), element="P1",
                            rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL)
    a, b = _both(prob)
    da, db = a.bone_displacement_mm[2], b.bone_displacement_mm[2]
    report("Nitsche vs VI, cylinder layer P1", d_nitsche=da, d_vi=db, rel=da / db - 1,
           area_nitsche=4 * a.contact_area_mm2, area_vi=4 * b.contact_area_mm2,
           peak_nitsche=a.peak_pressure_mpa, peak_vi=b.peak_pressure_mpa, n_dofs=a.n_dofs,
           wall_nitsche=a.wall_time_s, wall_vi=b.wall_time_s)
    assert da == pytest.approx(db, rel=3e-3)
    assert a.contact_area_mm2 == pytest.approx(b.contact_area_mm2, rel=0.06)
    assert a.peak_pressure_mpa == pytest.approx(b.peak_pressure_mpa, rel=0.03)


def test_vi_refuses_what_it_cannot_do(comm):
    """The VI path needs P1 and a coordinate-axis plane."""
    msh = meshes.box_slab(comm, 2.0, 2.0, 1.0, (1, 1, 1))
    kw = dict(mesh=msh, force_n=(0, 0, 1.0), **MATERIAL)
    with pytest.raises(ValueError, match="coordinate axis"):
        solve_contact_vi(FEContactProblem(obstacle=RigidPlane((0, 0, 1), (0, 0.1, -1)), **kw))
    with pytest.raises(ValueError, match="P1"):
        solve_contact_vi(FEContactProblem(obstacle=RigidPlane((0, 0, 1), (0, 0, -1)),
                                          element="P2", **kw))
