"""``stability``: stiff and extreme input, each case ending in its declared outcome, no NaN anywhere."""

from __future__ import annotations

import dataclasses

from edem.viscoelastic import CONTACT_SETS
from verification.campaign_model import Campaign, Case, Expect, uniform_basis
from verification.campaigns.edem_analytic import PLATE_AREA_MM2, PLATES, cylinder_tolerance
from verification.closed_forms import confined_modulus_mpa
from verification.verdicts import CLOSED_FORM

#: wall time, nothing cached: measured 39 s with 1 job at load 4-7 on the shared 2-core machine (81 cases;
#: before the creeping Kelvin-Voigt cases, 12 s with 2 jobs at load 5)
EXPECTED_TIME_S = 40.0


STABILITY_CHECKS = ("outcome_mismatch", "non_finite_outputs", "force_residual_rel")
STABILITY_TOL = {"outcome_mismatch": 0.0, "non_finite_outputs": 0.0, "force_residual_rel": 1e-8}
_FIELD = ("peak_pressure_rel_error", "displacement_rel_error", "pressure_l2_rel_error")
#: why the closed-form tolerances of the stability cases have their values, by reference side
_BASES = {
    "closed-form:flat-plates": uniform_basis(CLOSED_FORM, "flat plates, p = F/A and d = F h / (E' A): round-off (1e-8 where extreme moduli and loads widen the solve's range)", _FIELD),
    "closed-form:cylinder-plane": uniform_basis(
        CLOSED_FORM, f"faceting of the cylinder-plane-dem mesh (edem-analytic): 2 dx^2 / (8 R g) = {cylinder_tolerance(0.94)[0]['displacement_rel_error']:.2g}, stated as 0.01", _FIELD),
}
_VE_BASIS = uniform_basis(CLOSED_FORM, "Kelvin-Voigt springs with damping tau K: the pressure follows the load exactly, p = F/A, to round-off", _FIELD)


def _with_bases(case: Case) -> Case:
    bases = _VE_BASIS if case.name.startswith("ve-") else _BASES.get(case.sides[-1], {})
    return dataclasses.replace(case, basis={m: b for m, b in bases.items() if m in case.tolerance})


def _stability_cases() -> list[Case]:
    converges, closed = Expect("converges"), ("dem", "closed-form:flat-plates")
    plate_checks = STABILITY_CHECKS + ("peak_pressure_rel_error", "displacement_rel_error")
    plate_tol = {**STABILITY_TOL, "peak_pressure_rel_error": 1e-8, "displacement_rel_error": 1e-8}

    def refused(pattern: str) -> Expect:
        return Expect("refused", pattern)

    cases = []
    for nu in (0.49, 0.499, 0.4999):
        cases.append(Case(f"nu-{nu:g}", f"nearly incompressible, nu = {nu:g} (E' = {confined_modulus_mpa(10.35, nu):.4g} MPa)", PLATES, closed, plate_checks, plate_tol, {"cartilage.poissons_ratio": nu}, converges))
    # Linear springs solve any load, but an approach beyond the spring length (d = F h / (E' A) > h)
    # puts the plates through each other: refused by default, kept with a warning by the opt-in
    # key [solver] allow_bone_overlap (set here: the case studies that limit), and refused
    # whatever the key beyond the ray window h_max = 3.5 mm (edem.consistency: the pose leaves the
    # measured geometry).
    past_length = Expect("converges", warning=r"compressed past their length")

    def plate_outcome(force_n: float, youngs_modulus_mpa: float) -> Expect:
        approach_mm = force_n * 2.0 / (confined_modulus_mpa(youngs_modulus_mpa, 0.42) * PLATE_AREA_MM2)
        return refused(r"ray window") if approach_mm > 3.5 else past_length if approach_mm >= 2.0 else converges

    def plate_case(name: str, description: str, overrides: dict, expect: Expect) -> Case:
        if expect.outcome == "refused":  # no result to hold against the closed form
            return Case(name, description, PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, overrides, expect)
        if expect is past_length:  # the plates through each other: refused unless the study keeps it
            overrides = {**overrides, "solver.allow_bone_overlap": True}
        return Case(name, description, PLATES, closed, plate_checks, plate_tol, overrides, expect)

    for e in (0.01, 1e4):
        cases.append(plate_case(f"E-{e:g}", f"Young's modulus {e:g} MPa", {"cartilage.youngs_modulus_mpa": e}, plate_outcome(400.0, e)))
    for f in (0.0, 1e-6, 15000.0, 1e5):  # 15 kN: d = 2.8 mm, past h = 2 mm inside the window
        cases.append(plate_case(f"load-{f:g}", f"normal load {f:g} N (linear springs, d = F h / (E' A))", {"load.force_n": [0.0, 0.0, f]}, plate_outcome(f, 10.35)))
    cases += [
        Case(
            "load-1e5-gap-log",
            "1e5 N on the Blankevoort gap-log law (t = 2.5 mm): the springs stiffen, never pass t",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [0.0, 0.0, 1e5], "cartilage.law": "gap-log", "cartilage.thickness_mm": 2.5},
            converges,
        ),
        Case("pull-apart", "a load pulling the plates apart (-100 N)", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"load.force_n": [0.0, 0.0, -100.0]}, refused(r"no equilibrium")),
        Case(
            "tangential-no-shear",
            "tangential load, tx free, zero shear stiffness: singular, names tx",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [10.0, 0.0, 100.0], "constraints.fixed_dofs": ["ty", "rx", "ry", "rz"]},
            refused(r"nothing resists motion along tx"),
        ),
        Case(
            "tangential-with-shear",
            "the same tangential load with shear stiffness G = 1 MPa",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [10.0, 0.0, 100.0], "constraints.fixed_dofs": ["ty", "rx", "ry", "rz"], "cartilage.shear_modulus_mpa": 1.0},
            converges,
        ),
        Case("hmax-0.1-touching", "h_max = 0.1 mm, plates 0.05 mm apart", PLATES, closed, plate_checks, plate_tol, {"cartilage.max_spring_length_mm": 0.1, "geometry.gap_mm": 0.05}, converges),
        Case("hmax-0.1-apart", "h_max = 0.1 mm, plates 2 mm apart: no candidate", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"cartilage.max_spring_length_mm": 0.1}, refused(r"no spring is a candidate")),
        Case("far-apart-10mm", "plates 10 mm apart, h_max 3.5 mm: no candidate", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"geometry.gap_mm": 10.0}, refused(r"no spring is a candidate")),
        Case("far-apart-1m", "plates 1000 mm apart (a unit mismatch)", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"geometry.gap_mm": 1000.0}, refused(r"bodies too far apart")),
        Case(
            "interpenetrating-start",
            "the plane turned 30 deg about an axis 5 mm below the plate cuts through it (threshold law)",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"kinematics.axis_point_mm": [0.0, 0.0, -5.0], "kinematics.axis_direction": [1.0, 0.0, 0.0], "kinematics.angle_deg": -30.0},
            refused(r"compressed past their length"),
        ),
        Case(
            "compressed-past-length-edem",
            "EDEM, one increment compresses the springs 3 mm (> h = 2 mm): the next step refuses",
            PLATES,
            ("edem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.time_s": [0.0, 1.0, 2.0], "load.force_n": [[0.0, 0.0, 1.0], [0.0, 0.0, 3.0 * confined_modulus_mpa(10.35, 0.42) * PLATE_AREA_MM2 / 2.0], [0.0, 0.0, 16000.0]]},
            refused(r"compressed past their length"),
        ),
    ]
    cylinder = "cylinder-plane.toml"  # the idealised talus (3046 springs) under a plane, 333 N
    cases += [
        Case(
            "cylinder-nu-0.4999",
            "cylinder under a plane, nu = 0.4999: still the discrete foundation solution",
            cylinder,
            ("dem", "closed-form:cylinder-plane"),
            STABILITY_CHECKS + ("peak_pressure_rel_error", "displacement_rel_error"),
            {**STABILITY_TOL, "peak_pressure_rel_error": 0.01, "displacement_rel_error": 0.01},
            {"cartilage.poissons_ratio": 0.4999},
            converges,
        ),
        Case(
            "cylinder-axial-no-shear",
            "cylinder, 10 N along the axis with tx free and no shear stiffness: refused (faceting leaves the axis a "
            "tiny normal stiffness, so the refusal is 'no equilibrium' rather than naming tx)",
            cylinder,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [10.0, 0.0, 333.0], "constraints.fixed_dofs": ["ty", "rx", "ry", "rz"]},
            refused(r"nothing resists motion along tx|no equilibrium"),
        ),
    ]
    # Kelvin-Voigt springs over tau x dt (docs/method.md#4-viscoelastic-edem-thesis-chapter-6): ramp to 300 N in 3 steps, hold 2 steps.
    # The flat plates' contact set never changes, so the pressure is F/A at every time point with
    # every integrator (it follows the load). The thesis's frozen increment: exact converges
    # everywhere; RK2 for dt <= 2 tau, refused beyond. The creeping contact set: BDF2 and backward
    # Euler (L-stable) converge everywhere.
    for tau in (1e-4, 1e-2, 1.0, 1e2, 1e4):
        for dt in (1e-3, 1e-1, 1.0):
            ramp = {
                "load.time_s": [k * dt for k in range(6)],
                "load.force_n": [[0.0, 0.0, 100.0 * min(k, 3)] for k in range(6)],
                "viscoelastic.relaxation_time_s": tau,
            }
            for integrator in ("exact", "rk2", "bdf2", "backward-euler"):
                contact_set = next(name for name, each in CONTACT_SETS.items() if integrator in each.integrators)
                stable = integrator != "rk2" or dt <= 2.0 * tau
                cases.append(
                    Case(
                        f"ve-{integrator}-tau{tau:.0e}-dt{dt:.0e}",
                        f"viscoelastic EDEM, {contact_set} contact set, {integrator}, tau = {tau:g} s, dt = {dt:g} s (dt/tau = {dt / tau:.3g})",
                        PLATES,
                        ("edem", "closed-form:flat-plates"),
                        STABILITY_CHECKS + ("peak_pressure_rel_error", "pressure_l2_rel_error"),
                        {**STABILITY_TOL, "peak_pressure_rel_error": 1e-9, "pressure_l2_rel_error": 1e-9},
                        {**ramp, "viscoelastic.contact_set": contact_set, "viscoelastic.integrator": integrator},
                        converges if stable else refused(r"RK2 is unstable"),
                    )
                )
    return [_with_bases(case) for case in cases]


def campaign() -> Campaign:
    return Campaign(
        "stability",
        "Stiff and extreme input: each case ends in its declared outcome (converges with a small residual, or refused with a clear message) and no output holds a NaN.",
        tuple(_stability_cases()),
    )
