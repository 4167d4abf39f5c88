"""The biphasic layer in contact (fem_reference.biphasic_contact) against closed forms and invariants.

* Confined compression through a porous (free-draining) platen in frictionless contact is Mow's
  creep test (the closed form of tests/fem_reference/test_fe_biphasic.py): the same column, 8
  Taylor-Hood cells through its 2 mm, BDF2 at T / 100.
* Through an impermeable platen covering the whole face the fluid cannot leave: no creep at all.
* A quarter slab indented by a rigid cylinder (impermeable, its contact face drained where it is
  not in contact, the free faces drained): its first instant is the incompressible elastic contact
  of the same layer (shear modulus mu), its equilibrium the drained elastic contact (P2, the same
  Nitsche gamma): both exact invariants of the discrete problem, not mesh-dependent comparisons.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import report  # noqa: E402

from fem_reference import FEContactProblem, RigidCylinder, RigidPlane, Roller, meshes, solve_contact  # noqa: E402
from fem_reference import closed_forms as cf  # noqa: E402
from fem_reference.biphasic import BiphasicMaterial  # noqa: E402
from fem_reference.biphasic_contact import solve_history  # noqa: E402
from fem_reference.contact import nitsche_modulus_mpa  # noqa: E402
from fem_reference.problem import NitscheParameters, SolverOptions  # noqa: E402

pytestmark = pytest.mark.fe

H, WIDTH, STRESS = 2.0, 0.5, 0.1
COLUMN = BiphasicMaterial.from_aggregate_modulus(0.7, 0.05, 1e-3)
T = COLUMN.consolidation_time_s(H)
#: how far from 1 the fluid's share of the load may be where no fluid can have left: round-off of the
#: sealed column's solve (only Nitsche's gamma holds it in z, so its conditioning amplifies the last
#: digits: 2.1e-9 at the undrained first instant with the PyPI wheels of 2026-11-29, dolfinx-solver-real
#: 0.11.0.post0 and numpy 2.5.5, under 1e-9 with those before), an order of magnitude below this bound;
#: a drained face or a leak is not small (through the porous platen the share is 0.005 one step of T / 100 later)
UNDRAINED_SHARE_TOL = 1e-8


def _column_problem(comm):
    mesh = meshes.box_slab(comm, WIDTH, WIDTH, H, (1, 1, 8))
    return FEContactProblem(mesh=mesh, youngs_modulus_mpa=COLUMN.youngs_modulus_mpa, poissons_ratio=COLUMN.poissons_ratio,
                            obstacle=RigidPlane((0.0, 0.0, H), (0.0, 0.0, -1.0)), force_n=(0.0, 0.0, STRESS * WIDTH**2),
                            rollers=(Roller(4, "x"), Roller(5, "y")), element="TH")


def test_confined_creep_through_a_porous_platen_contact_is_mows(comm):
    """8 cells, BDF2, T / 100 to 1.5 T, the load applied at t = 0 (undrained start). The bone's
    displacement within 1.1 % of sigma0 h / H_A of Mow's series at every instant (measured
    0.76 %, at the first step: the standalone biphasic FE errs by 0.73 % there, the weak p = 0 of
    the platen adding 0.03 %; the tolerance is 1.4 times the measured error, as that test's);
    the undrained instant does not move (the fluid carries the whole load)."""
    times = np.linspace(0.0, 1.5 * T, 151)
    force = np.array([0.0, 0.0, STRESS * WIDTH**2])
    steps = solve_history(_column_problem(comm), times, [force] * len(times), COLUMN.permeability_mm4_per_n_s,
                          counter_surface="porous", drained_tags=())
    u = np.array([s.result.bone_displacement_mm[2] for s in steps])
    u_exact, _ = cf.biphasic_confined_creep(times, H, COLUMN.aggregate_modulus_mpa, COLUMN.permeability_mm4_per_n_s, STRESS)
    u_inf = STRESS * H / COLUMN.aggregate_modulus_mpa
    err = np.abs(u - u_exact).max() / u_inf
    report("biphasic contact: confined creep through a porous platen (8 cells, T/100)", max_err_u=err,
           u_end=u[-1], u_inf=u_inf, fluid_at_instant=steps[0].fluid_load_fraction)
    assert err < 0.011
    assert abs(u[0]) < 1e-9 * u_inf  # TH holds div u = 0 against the constants: the column cannot shorten
    assert steps[0].fluid_load_fraction == pytest.approx(1.0, abs=UNDRAINED_SHARE_TOL)


def test_an_impermeable_platen_on_a_confined_column_allows_no_creep(comm):
    """The platen covers the whole face and seals it, the bottom and the walls are impermeable:
    no fluid can leave, so the column keeps its undrained length (0) and the fluid the whole load
    at every instant (the share: UNDRAINED_SHARE_TOL). Bound 1e-9 of sigma0 h / H_A: Newton's tolerance (rtol 1e-10). The sealed
    column is rigid in z (only Nitsche's gamma holds it), so its residual stalls at round-off,
    6e-13 N = 3e-11 of the load, above the default absolute tolerance (1e-11 of the load): 1e-9 here."""
    times = np.array([0.0, 0.01, 0.1, 1.0]) * T
    force = np.array([0.0, 0.0, STRESS * WIDTH**2])
    problem = dataclasses.replace(_column_problem(comm), solver=SolverOptions(atol_rel_to_load=1e-9))
    steps = solve_history(problem, times, [force] * len(times), COLUMN.permeability_mm4_per_n_s,
                          counter_surface="impermeable", drained_tags=())
    u = np.array([s.result.bone_displacement_mm[2] for s in steps])
    assert np.abs(u).max() < 1e-9 * STRESS * H / COLUMN.aggregate_modulus_mpa
    assert [s.fluid_load_fraction for s in steps] == pytest.approx([1.0] * len(steps), abs=UNDRAINED_SHARE_TOL)


# ---- indentation of a free slab by a rigid cylinder ----

#: drained Poisson's ratio 0: the bulk form's lambda (div u, div v) term vanishes, so the undrained
#: instant is exactly the Taylor-Hood incompressible elastic problem (with lambda > 0 the two
#: discrete forms differ where div u vanishes only weakly: 4e-4 of the displacement at nu 0.05)
SLAB = BiphasicMaterial.from_aggregate_modulus(0.7, 0.0, 1e-3)
SLAB_H, SLAB_L, CYLINDER_R, LOAD = 1.0, 4.0, 10.0, 0.1


def test_indentation_starts_incompressible_and_ends_drained(comm):
    """Quarter slab 4 x 4 x 1 mm (8 x 8 x 2 cells), rigid cylinder R 10 mm, 0.1 N on the quarter,
    BDF2 on 26 times from 1e-3 T to 100 T (step ratio 1.58 < 1 + sqrt 2, BDF2's zero-stability
    bound for variable steps).

    * t = 0: the incompressible elastic contact (Taylor-Hood, shear modulus mu, nu = 0.5 - 1e-7,
      the same Nitsche gamma): displacement, peak and area within 2e-6 (measured 4.2e-7; the
      twin's compressibility mu / lambda is 2e-7);
    * t = 100 T: the drained elastic contact (P2, the matrix's E and nu): within 1e-5 (measured
      6.2e-7, the transient left);
    * between them the patch widens (the area at the end exceeds the instant's by 29 %) and the
      fluid's share of the contact load falls from 71 % to 0 (within 1 %)."""
    mesh = meshes.box_slab(comm, SLAB_L, SLAB_L, SLAB_H, (8, 8, 2), confined=False, quarter=True)
    base = FEContactProblem(mesh=mesh, youngs_modulus_mpa=SLAB.youngs_modulus_mpa, poissons_ratio=SLAB.poissons_ratio,
                            obstacle=RigidCylinder((0.0, 0.0, SLAB_H + CYLINDER_R), (0.0, 1.0, 0.0), CYLINDER_R),
                            force_n=(0.0, 0.0, LOAD), rollers=(Roller(4, "x"), Roller(5, "y")), element="TH")
    t_slab = SLAB.consolidation_time_s(SLAB_H)
    times = np.concatenate([[0.0], t_slab * np.geomspace(1e-3, 1e2, 26)])
    steps = solve_history(base, times, [base.force_n] * len(times), SLAB.permeability_mm4_per_n_s)
    first, last = steps[0].result, steps[-1].result

    lam, mu = base.lame()
    nu_u = 0.5 - 1e-7
    e_u = 2.0 * mu * (1.0 + nu_u)
    lam_u = e_u * nu_u / ((1.0 + nu_u) * (1.0 - 2.0 * nu_u))
    # the same gamma as the biphasic step's (its drained matrix's lambda + 2 mu; the undrained
    # Taylor-Hood body's penalty scales with 2 mu)
    gamma0 = NitscheParameters().gamma0 * nitsche_modulus_mpa("TH", lam, mu, own_bulk=True) / nitsche_modulus_mpa("TH", lam_u, mu)
    undrained = solve_contact(dataclasses.replace(base, youngs_modulus_mpa=e_u, poissons_ratio=nu_u,
                                                  nitsche=NitscheParameters(gamma0=gamma0)))
    drained = solve_contact(dataclasses.replace(base, element="P2"))
    errors = {}
    for name, step, elastic in (("undrained", first, undrained), ("drained", last, drained)):
        errors[name] = max(abs(step.bone_displacement_mm[2] / elastic.bone_displacement_mm[2] - 1.0),
                           abs(step.peak_pressure_mpa / elastic.peak_pressure_mpa - 1.0),
                           abs(step.contact_area_mm2 / elastic.contact_area_mm2 - 1.0))
    report("biphasic indentation: instant and equilibrium", undrained_err=errors["undrained"], drained_err=errors["drained"],
           area_ratio=last.contact_area_mm2 / first.contact_area_mm2, fluid_at_instant=steps[0].fluid_load_fraction)
    assert errors["undrained"] < 2e-6
    assert errors["drained"] < 1e-5
    assert last.contact_area_mm2 > 1.2 * first.contact_area_mm2
    assert steps[0].fluid_load_fraction > 0.5
    assert abs(steps[-1].fluid_load_fraction) < 0.01
