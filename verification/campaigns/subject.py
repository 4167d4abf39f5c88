"""``subject``: standing and toe-off on the subject-like ankle, DEM and EDEM vs the FE slab (P2,
1.0 mm), without ligaments (the FE models none), toe-off with ``ty`` fixed on both sides (its
load has an antero-posterior component the frictionless FE cannot resist otherwise). Each with
independent springs (``<scene>-<method>-vs-fe``, ``cartilage.coupling = "none"``) and with the coupled
thin layer (``<scene>-<method>-coupled-vs-fe``, ``cartilage.coupling = "thin-layer"``, the scenes' default), each bed
named by the overrides; the four cases of a
scene share one FE run (the FE never reads the coupling: verification.runner's side store)."""

from __future__ import annotations

from verification.campaign_model import COUPLED_BED, THESIS_ANKLE, THESIS_BED, Analysis, Campaign
from verification.fe_comparison import FE_COARSE, FE_ERROR_COLUMNS, fe_comparison_case

#: wall time with 2 jobs on 2 cores, nothing cached (measured: 66 s at load 3-5 on the shared 2-core machine, its 8
#: cases running 2 FE runs; before the coupled cases and the shared FE, 136 s for 4 cases running 4)
EXPECTED_TIME_S = 66.0
#: the bed's variants: (name suffix, overrides, what)
COUPLINGS = (("", THESIS_BED, "independent springs"), ("-coupled", COUPLED_BED, "coupled thin layer"))


SUBJECT_SCENES = (
    ("subject-standing", {"ligaments": []}, "333 N vertical at 0 deg; scene constraints (tx, rx, ry, rz fixed)"),
    ("subject-toe-off", {"ligaments": [], "constraints.fixed_dofs": ["tx", "ty", "rx", "ry", "rz"]}, "4190 N at 16.31 deg; ty fixed on both sides too (the load's antero-posterior component: the frictionless FE cannot resist it)"),
)


def campaign() -> Campaign:
    cases = []
    for scene, overrides, what in SUBJECT_SCENES:
        for suffix, coupling, bed in COUPLINGS:
            for method in ("dem", "edem"):
                cases.append(
                    fe_comparison_case(
                        f"{scene}-{method}{suffix}-vs-fe",
                        f"{scene}: {method.upper()} ({bed}) vs the FE slab (P2, 1.0 mm), {what}; ligaments removed from the discrete side (the FE models none). Generous tolerances",
                        scene,
                        (method, "fe-slab"),
                        overrides={**overrides, **THESIS_ANKLE, **coupling},  # the threshold law on the thesis kind of plafond: the FE slab's twin
                        options=FE_COARSE,
                        maps=method == "dem",
                    )
                )
    columns = [
        {"header": "discrete regularised peak (MPa)", "metric": "a_at_b_regularised_peak_pressure_mpa"},
        {"header": "FE regularised peak (MPa)", "metric": "b_regularised_peak_pressure_mpa"},
        {"header": "regularised peak err", "metric": "regularised_peak_pressure_rel_error"},
        {"header": "raw peak err (reported only)", "metric": "peak_pressure_rel_error"},
        {"header": "mean p err", "metric": "mean_pressure_rel_error"},
        {"header": "discrete area (cm^2)", "metric": "a_at_b_mean_contact_area_mm2", "scale": 0.01},
        {"header": "FE area (cm^2)", "metric": "b_mean_contact_area_mm2", "scale": 0.01},
        {"header": "area err", "metric": "contact_area_rel_error"},
        {"header": "discrete |u| (mm)", "metric": "a_at_b_displacement_norm_mm"},
        {"header": "FE |u| (mm)", "metric": "b_displacement_norm_mm"},
        {"header": "disp err", "metric": "displacement_rel_error"},
        {"header": "L2 err", "metric": "pressure_l2_rel_error"},
        *FE_ERROR_COLUMNS,
    ]
    names = tuple(c.name for c in cases)
    return Campaign(
        "subject",
        "Standing and toe-off on the subject-like ankle: DEM and EDEM (no ligaments), independent springs and coupled thin layer, vs the FE slab (P2, 1.0 mm); toe-off with ty fixed on both sides.",
        tuple(cases),
        (),
        (Analysis("subject-metrics", "Subject-like ankle: discrete vs FE slab, the comparison metrics. Reported, no verdict", "table", names, {"columns": columns}),),
    )


# ---------------------------------------------------------------------------------------------
