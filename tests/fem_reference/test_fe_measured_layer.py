"""The FE layer model on measured cartilage (fem_reference.models, geometries.cartilage_solids):
the solid between a body's articular surface and its subchondral bone, bonded to the bone, F rigid.

Closed form: at nu = 0 a free-sided layer is in exact uniaxial strain, so a plate whose bone lies
t below its articular surface, a gap g from a rigid plane, answers d = g + (F / A) t / E at
every node (P1 reproduces the linear field). Invariant: a measured uniform layer is the same FE
problem as the uniform layer model of that thickness (same mesh, same answer to round-off).
Refusals: a layer on F (the FE takes F rigid) exits 2 naming the key.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from edem.cli import main  # noqa: E402
from fem_reference.scene_run import run_scene  # noqa: E402
from support import grid_plate, make_scene, plane  # noqa: E402

pytestmark = pytest.mark.fe

E = 10.35
T_MM, GAP_MM = 1.5, 0.5
FORCE_N = 100.0  # on the 10 x 10 mm plate: p = 1 MPa
PLATE_FIXED = ("tx", "ty", "rx", "ry", "rz")


def measured_plate(nu: float):
    """The articular plate at z = 0 with its bone T_MM below, a rigid plane GAP_MM above."""
    bone = plane(lambda x, y: -T_MM)
    return make_scene(grid_plate(10.0, 10.0, 5), plane(lambda x, y: GAP_MM), (0.0, 0.0, FORCE_N), law="gap",
                      poissons_ratio=nu, fixed_dofs=PLATE_FIXED, mobile_bone=(bone.vertices_mm, bone.triangles),
                      fixed_thickness_mm=0.0)


def uniform_plate(nu: float):
    """The same cartilage as a uniform layer on the bone plate (the scene surface is the bone)."""
    return make_scene(grid_plate(10.0, 10.0, 5, z_mm=-T_MM), plane(lambda x, y: GAP_MM), (0.0, 0.0, FORCE_N), law="gap",
                      poissons_ratio=nu, fixed_dofs=PLATE_FIXED, thickness_mm=T_MM)


def test_measured_layer_at_nu0_is_exact_uniaxial_strain():
    run = run_scene(measured_plate(0.0), model="layer", degree=1, mesh_size_mm=2.0, layers_through_thickness=1)
    step = run.steps[0]
    # 1e-8: a linear field that P1 reproduces; the Newton solve ends at the 1e-10-relative residual
    assert step.displacement_mm[2] == pytest.approx(GAP_MM + FORCE_N / 100.0 * T_MM / E, rel=1e-8)
    assert step.peak_pressure_mpa == pytest.approx(FORCE_N / 100.0, rel=1e-8)
    assert step.contact_area_mm2 == pytest.approx(100.0, rel=1e-9)


def test_measured_uniform_layer_is_the_uniform_layer_model():
    measured = run_scene(measured_plate(0.42), model="layer", degree=1, mesh_size_mm=2.0, layers_through_thickness=2).steps[0]
    uniform = run_scene(uniform_plate(0.42), model="layer", degree=1, mesh_size_mm=2.0, layers_through_thickness=2).steps[0]
    # the same tetrahedra and load: equal to the solves' round-off (Newton residual 1e-10 relative)
    np.testing.assert_allclose(measured.displacement_mm, uniform.displacement_mm, rtol=1e-8, atol=1e-12)
    assert measured.peak_pressure_mpa == pytest.approx(uniform.peak_pressure_mpa, rel=1e-8)
    assert measured.contact_area_mm2 == pytest.approx(uniform.contact_area_mm2, rel=1e-9)
    # nu 0.42 on a 10 mm wide, 1.5 mm thick free-sided layer: stiffer than uniaxial, softer than confined
    d = measured.displacement_mm[2] - GAP_MM
    assert T_MM / (E * (1 - 0.42) / ((1 + 0.42) * (1 - 2 * 0.42))) < d < T_MM / E


def test_on_a_curved_articular_surface_the_area_on_m_is_the_contact_face_s():
    """With a bone mesh under M the scene's M is the articular surface, which is the layer's
    contact face: the FE's contact area and pressure measured on M (where the springs live) are
    its own, not the bone's (a sphere cap of R 20 mm over a bone 1.5 mm inside it, whose columns
    narrow by (18.5 / 20)^2 = 0.86 towards the bone), to round-off."""
    from support import grid_plate, make_scene

    plate = grid_plate(12.0, 12.0, 8)
    x, y = plate.vertices_mm[:, 0], plate.vertices_mm[:, 1]

    def cap(radius: float):
        return np.column_stack([x * radius / 20.0, y * radius / 20.0, np.sqrt(radius**2 - (x * radius / 20.0) ** 2 - (y * radius / 20.0) ** 2) - 20.0])

    from geometries.surface import TriangleSurface

    articular = TriangleSurface(cap(20.0), plate.triangles)
    bone = cap(20.0 - T_MM)
    scene = make_scene(articular, plane(lambda x, y: 0.05), (0.0, 0.0, 150.0), law="gap", poissons_ratio=0.3, fixed_dofs=PLATE_FIXED,
                       mobile_bone=(bone, plate.triangles), fixed_thickness_mm=0.0)
    run = run_scene(scene, model="layer", degree=1, mesh_size_mm=2.0, layers_through_thickness=1)
    step = run.steps[0]
    assert step.contact_area_mm2 > 10.0  # a patch, not a point
    assert step.contact_area_on_mobile_mm2 == pytest.approx(step.contact_area_mm2, rel=1e-12)
    np.testing.assert_allclose(step.point_data["mobile_point_mm"], step.points_mm, atol=1e-12)
    np.testing.assert_allclose(step.point_data["pressure_on_mobile_mpa"], step.point_data["pressure_mpa"], rtol=1e-12, atol=1e-15)
