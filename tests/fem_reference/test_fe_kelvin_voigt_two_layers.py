"""The Kelvin-Voigt FE twin of two deformable layers (fem_reference.viscoelastic on
fem_reference.two_body; docs/method.md#the-viscoelastic-twin-kelvin-voigt-continuum).

Both layers creep with one tau, so a stack of them is one Kelvin-Voigt element whose compliance
is the sum of the layers': confined, tau du/dt + u = F (h_M / E'_M + h_F / E'_F) / A; free-sided
at nu 0, F (h_M + h_F) / (E A). Its exact solution for a piecewise-linear load is
fem_reference.closed_forms.kelvin_voigt_creep. The uniform strains lie in every element's space,
so the differences are the time scheme's. Invariants: loaded and unloaded, the bone returns to
its start (both layers creep back, F's on its held bone); held long, a curved contact is the
elastic two-layer solution.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import report  # noqa: E402

from fem_reference import FEContactProblem, FEMesh, Roller, meshes, solve_contact  # noqa: E402
from fem_reference import closed_forms as cf  # noqa: E402
from fem_reference.problem import DeformableCounterpart  # noqa: E402
from fem_reference.viscoelastic import solve_history  # noqa: E402

pytestmark = pytest.mark.fe

CARTILAGE = (10.35, 0.42)  # docs/references.md#the-thesiss-figures
SOFT = (5.0, 0.3)  # F's own material, so that each layer's compliance shows in the sum
ROLLERS = (Roller(4, "x"), Roller(5, "y"))
TAU = 1.0
LX, LY, H_M, H_F, LOAD = 10.0, 8.0, 2.0, 1.0, 120.0
#: ramp over tau, hold tau, unload over tau: every kink on a time point of the grids below
TRAPEZOID = (np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.0, LOAD, LOAD, 0.0]))


def _problem(solid, comm, mobile, fixed, **kw) -> FEContactProblem:
    mesh, cell_tags, facet_tags = solid.to_dolfinx(comm)
    return FEContactProblem(mesh=FEMesh(mesh, facet_tags, cell_tags), youngs_modulus_mpa=mobile[0], poissons_ratio=mobile[1],
                            obstacle=DeformableCounterpart.from_solid(solid, *fixed), force_n=(0.0, 0.0, -1.0), **kw)


@pytest.mark.parametrize("element", ["P1", "TH"])
@pytest.mark.parametrize("gap", [0.0, 0.05])
def test_confined_two_layer_stack_creeps_as_one_kelvin_voigt_with_the_summed_compliance(comm, element, gap):
    """M's 2 mm layer (E 10.35, nu 0.42) on F's 1 mm (E 5, nu 0.3), confined, under the trapezoid
    and 2 tau unloaded (trapezoidal scheme, dt tau/8), then unloaded to 12 tau at dt tau: the bone's
    displacement is gap + kelvin_voigt_creep of F (h_M / E'_M + h_F / E'_F) / A at every instant,
    the unloaded ones too (the bone follows the layers back, touching them without force).
    Tolerance 1 % of the largest creep, the one-body test's: the trapezoid is second order through
    the load's kinks (0.08 % at tau/8 here; at dt = tau its decay is 1/3 a step against exp(-1):
    2.4 % of the creep when taken right after unloading, 0.33 % from 5 tau on, the largest
    measured). Back at its start after 12 tau: within 1e-3 of the creep (exp(-12) = 6e-6 left in
    the closed form; measured 1e-5 mm of 0.27 mm)."""
    solid = meshes.two_layer_stack(LX, LY, H_M, H_F, (5, 4), (2, 1), gap=gap)
    base = _problem(solid, comm, CARTILAGE, SOFT, element=element, rollers=ROLLERS)
    t = np.concatenate([np.arange(0.0, 5.0, 0.125), np.arange(5.0, 12.0 + 1e-9, 1.0)])
    force = np.zeros((len(t), 3))
    force[:, 2] = -np.interp(t, *TRAPEZOID)
    steps = solve_history(base, t, force, TAU, "trapezoidal", comm)
    compliance = (H_M / cf.confined_modulus(*CARTILAGE) + H_F / cf.confined_modulus(*SOFT)) / (LX * LY)
    creep = cf.kelvin_voigt_creep(t, TRAPEZOID[0], compliance * TRAPEZOID[1], TAU)
    d = np.array([-s.translation_mm[2] for s in steps])
    err = np.abs(d[1:] - gap - creep[1:]).max() / creep.max()
    report(f"KV two-layer confined stack {element} gap {gap}", max_rel_err=err, d_max=d.max(), d_end=d[-1], creep_max=creep.max())
    assert err < 0.01
    loaded = [s for s in steps[1:] if s.result is not None]
    for s in loaded:  # the plate carries the load at every instant: p = F / A (the force balance's 1e-6)
        assert s.result.peak_pressure_mpa == pytest.approx(abs(s.result.applied_force_n[2]) / (LX * LY), rel=1e-6)
    assert steps[-1].result is None and abs(d[-1] - gap) < 1e-3 * creep.max()


def test_scene_two_layers_at_nu0_creep_as_uniaxial_kelvin_voigt_and_return_to_the_start():
    """``edem fe`` on a scene with cartilage on both bones and ``[viscoelastic]`` (the two-layer
    Kelvin-Voigt twin): free-sided 10 x 10 mm plates of 1.5 + 1 mm at nu 0 are in uniaxial strain,
    so M's bone moves by GAP + kelvin_voigt_creep of F (T_M + T_F) / (E A), 1 % of the creep (the
    trapezoid's at dt tau/4, then tau from 5 tau on, as above); then unloaded to 12 tau it is back
    at GAP, touching the undeformed layers (1e-3 of the creep, as above)."""
    from dataclasses import replace

    from edem.scene import Viscoelastic
    from fem_reference.scene_run import run_scene
    from support import grid_plate, make_scene, plane

    t_m, t_f, gap, load = 1.5, 1.0, 0.5, 100.0
    t = np.concatenate([np.arange(0.0, 5.0, 0.25), np.arange(5.0, 12.0 + 1e-9, 1.0)])
    force = np.zeros((len(t), 3))
    force[:, 2] = np.interp(t, TRAPEZOID[0], TRAPEZOID[1] / LOAD * load)
    scene = make_scene(grid_plate(10.0, 10.0, 5, z_mm=-t_m), plane(lambda x, y: gap + t_f), force, time_s=t, law="gap",
                       poissons_ratio=0.0, fixed_dofs=("tx", "ty", "rx", "ry", "rz"), mobile_thickness_mm=t_m,
                       fixed_thickness_mm=t_f, viscoelastic=Viscoelastic(TAU))
    scene = replace(scene, fe={"time_scheme": "trapezoidal"})  # as the scene file's [fe] table
    run = run_scene(scene, degree=1, mesh_size_mm=2.0, layers_through_thickness=1)
    assert run.settings.model == "two-layer"
    d = np.array([s.displacement_mm[2] for s in run.steps])
    creep = cf.kelvin_voigt_creep(t, TRAPEZOID[0], TRAPEZOID[1] / LOAD * load * (t_m + t_f) / (CARTILAGE[0] * 100.0), TAU)
    err = np.abs(d[1:] - gap - creep[1:]).max() / creep.max()
    report("KV two-layer scene nu 0", max_rel_err=err, d_end=d[-1], creep_max=creep.max())
    assert err < 0.01
    assert abs(d[-1] - gap) < 1e-3 * creep.max()


def test_two_layers_creep_from_a_narrow_contact_to_the_elastic_two_layer_one(comm):
    """A cylindrical 1 mm layer (bone R 20 mm) on a flat 1 mm layer (F: E 5, nu 0.3), plane strain,
    P2, a step held 12 tau (BDF2, dt tau/4 to tau, then tau, where BDF2's roots are complex and the
    approach overshoots its end by a few per cent before it settles): the contact starts narrow with a high
    peak (both layers' dashpots stiffen them) and widens as they creep to the elastic two-layer
    solution under the same load. At a steady state v = u and the problem is the elastic one but
    for Nitsche's stress-stress term weighted c0 / gamma (the one-body test's reasoning and
    tolerances: 0.2 % displacement, 1 % peak and area); the creep left at 12 tau is exp(-12)."""
    kw = dict(bone_radius=20.0, mobile_thickness=1.0, fixed_thickness=1.0, half_angle_deg=30.0, n_arc=30,
              arc_progression=1.08, slice_thickness=0.2, layers=(2, 2))
    solid, _ = meshes.cylinder_on_flat_layers(**kw)
    load = 333.0 / 30.0 * 0.2 / 2.0  # 333 N over 30 mm, half model of a 0.2 mm slice
    base = _problem(solid, comm, CARTILAGE, SOFT, element="P2", rollers=ROLLERS)
    from dataclasses import replace

    elastic = solve_contact(replace(base, force_n=(0.0, 0.0, -load)), comm, keep_fields=False)
    t = np.concatenate([np.arange(0.0, 1.0, 0.25), np.arange(1.0, 12.0 + 1e-9, 1.0)])
    force = np.zeros((len(t), 3))
    force[1:, 2] = -load
    steps = solve_history(base, t, force, TAU, "bdf2", comm)
    area = np.array([s.result.contact_area_mm2 for s in steps[1:]])
    peak = np.array([s.result.peak_pressure_mpa for s in steps[1:]])
    d = np.array([-s.translation_mm[2] for s in steps])
    report("KV two layers, cylinder on a flat layer", area_first=area[0], area_end=area[-1], area_elastic=elastic.contact_area_mm2,
           peak_first=peak[0], peak_end=peak[-1], peak_elastic=elastic.peak_pressure_mpa, d_end=d[-1],
           d_elastic=-elastic.bone_displacement_mm[2])
    assert area[0] < 0.8 * elastic.contact_area_mm2 and peak[0] > 1.2 * elastic.peak_pressure_mpa
    assert d[-1] == pytest.approx(-elastic.bone_displacement_mm[2], rel=2e-3)
    assert peak[-1] == pytest.approx(elastic.peak_pressure_mpa, rel=0.01)
    assert area[-1] == pytest.approx(elastic.contact_area_mm2, rel=0.01)
