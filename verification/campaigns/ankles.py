"""``ankles``: the built-in ankles on their cartilage against their FE twin, both layers deformable
(docs/campaigns.md#ankles-the-cartilage-ankles-against-their-fe-twin).

The ideal and subject-like ankles standing (``ideal-standing``, ``subject-standing``: talar and
tibial cartilage tapered to zero at their margins, the gap law on both measured layers) at
Poisson's ratio :data:`NUS`, loaded 333, 1000 and 2000 N as the three time points of one run
(:data:`LOADS_N`: the FE solves them in turn from the last solution), no ligaments (the FE models
none). Each bed of :data:`BEDS` (the scenes' default, the coupled layer as a sandwich of the two
layers, and the independent springs) against the two-layer FE (``fe-two-layer``: both layers
elastic, each bonded to its bone, frictionless between them; P2 at 0.7 mm, M's triangles halved,
Taylor-Hood from nu 0.49: :data:`FE_ANKLES`), one FE run per ankle and nu shared by the beds. Each case is judged against the model band
(:func:`verification.fe_comparison.banded`) over its three loads, the FE's own error from
``fe-convergence``; the analysis ``goal`` gives every load apart, against the 10 % goal where the
FE's own error is below it, and the contact area's growth from 333 to 2000 N (at least
:data:`AREA_GROWTH` times, DEM and FE), and beside the coupled bed's errors its deflection under
the FE's own pressure against the FE's (:mod:`verification.bed_compliance`: the bed's operator
without the contact solve). The analysis ``lumping`` measures the lumping error on the
ankles: the FE of one layer of the summed thickness on the talus (``fe-lumped``) against the
two-layer FE (the beds' run).

For another campaign: :func:`ankle_case_name` and :func:`ankle_cases` (any ankles, beds, nus,
options) build these cases; :func:`case_names` lists them.
"""

from __future__ import annotations

from typing import Any

from verification.bed_compliance import BED_COMPLIANCE_QUANTITIES
from verification.campaign_model import COUPLED_BED, THESIS_BED, Analysis, Campaign, Case
from verification.fe_comparison import FE_TABLE_COLUMNS, banded, fe_comparison_case, with_bed_compliance

#: wall time with 2 jobs on 2 cores, nothing cached: an estimate, the whole campaign not yet run at :data:`FE_ANKLES`
#: (2026-11-28: the fe-convergence study's two-layer runs at 0.7 mm took 614-1456 s each, 6.8k s for the six, at
#: load 2-5, and as many lumped runs of about as many DOFs: docs/campaigns.md#ankles-the-cartilage-ankles-against-their-fe-twin)
EXPECTED_TIME_S = 7200.0

#: the ankles: case-name prefix -> (scene, what)
ANKLES = {"ideal": ("ideal-standing", "ideal ankle"), "subject": ("subject-standing", "subject-like ankle")}
NUS = (0.3, 0.42, 0.49)
#: the loads, the three time points of one run (t = 0, 1, 2 s)
LOADS_N = (333.0, 1000.0, 2000.0)
#: the beds: case-name word -> (overrides, what); the first is the scenes' default
BEDS = {
    "sandwich": ({**COUPLED_BED, "cartilage.thin_layer_stack": "sandwich"}, "coupled layer (the two layers as a sandwich, Pade)"),
    "springs": (dict(THESIS_BED), "independent springs"),
}
#: the beds' FE: M's triangles halved, two P2 elements through each layer (Taylor-Hood from nu 0.49). On M's own
#: triangles (1.0 mm) the talus slides antero-posteriorly under the vertical load by a mesh-dependent 2.5-5.3 um on
#: the ideal ankle at 333 N (0.1-0.4 um on these; the two displacements differ by 8.6 % at nu 0.49: docs/campaigns.md)
FE_ANKLES = {"mesh_size_mm": 0.7, "degree": 2}
#: the goal on each load: displacement, regularised peak and contact area within 10 % of the FE
GOAL_REL = 0.10
#: the contact area at 2000 N at least this many times the area at 333 N, DEM and FE
AREA_GROWTH = 1.25
GOAL_QUANTITIES = (("displacement", "displacement_rel_error"), ("regularised peak", "regularised_peak_pressure_rel_error"),
                   ("contact area", "contact_area_rel_error"))
REPORTED_QUANTITIES = (("pressure L2", "pressure_l2_rel_error"),)


def load_history(loads_n: tuple[float, ...] = LOADS_N) -> dict[str, Any]:
    """The overrides that load the ankle by ``loads_n`` (vertical, N) at t = 0, 1, 2... s."""
    return {"load.time_s": [float(k) for k in range(len(loads_n))], "load.force_n": [[0.0, 0.0, float(f)] for f in loads_n]}


def ankle_overrides(ankle: str, nu: float) -> dict[str, Any]:
    """The FE's problem on ``ankle`` at ``nu``: its loads, no ligaments (the FE models none)."""
    return {"ligaments": [], "cartilage.poissons_ratio": nu, **load_history()}


def ankle_case_name(ankle: str, bed: str, nu: float) -> str:
    """The case of ``bed`` (a key of :data:`BEDS`) against the two-layer FE on ``ankle`` (a key of
    :data:`ANKLES`) at ``nu``, e.g. ``ideal-cartilage-nu0.42-sandwich``."""
    return f"{ankle}-cartilage-nu{nu:g}-{bed}"


def lumping_case_name(ankle: str, nu: float) -> str:
    """The case of the lumped FE against the two-layer FE on ``ankle`` at ``nu``, e.g. ``ideal-cartilage-nu0.42-lumping``."""
    return f"{ankle}-cartilage-nu{nu:g}-lumping"


def ankle_cases(ankles: tuple[str, ...] = tuple(ANKLES), beds: tuple[str, ...] = tuple(BEDS), nus: tuple[float, ...] = NUS,
                options: dict[str, Any] | None = None) -> list[Case]:
    """DEM with each bed against the two-layer FE on each ankle and nu (:func:`ankle_case_name`),
    banded (:func:`verification.fe_comparison.banded`); the FE at ``options`` (default
    :data:`FE_ANKLES`). The beds of an ankle and nu share one FE run."""
    options = dict(FE_ANKLES if options is None else options)
    cases = []
    for nu in sorted(nus, reverse=True):  # the slowest FE (Taylor-Hood) first
        for ankle in ankles:
            scene, where = ANKLES[ankle]
            for bed in beds:
                overrides, what = BEDS[bed]
                element = "Taylor-Hood P2-P1" if nu >= 0.49 else "P2"
                case = banded(fe_comparison_case(
                    ankle_case_name(ankle, bed, nu),
                    f"{where} standing on its cartilage, gap law, {what}: DEM vs the two-layer FE (both layers deformable) at "
                    f"{', '.join(f'{f:g}' for f in LOADS_N)} N (one run), nu {nu:g}, no ligaments; FE {element} at {options['mesh_size_mm']:g} mm",
                    scene, ("dem", "fe-two-layer"), overrides={**ankle_overrides(ankle, nu), **overrides}, options=options,
                    params={"poissons_ratio": nu}, maps=(ankle == "ideal" and bed == "sandwich" and nu == 0.42)))
                # the coupled bed's operator under the FE's own pressure (verification.bed_compliance; reported)
                coupled = overrides.get("cartilage.coupling") == COUPLED_BED["cartilage.coupling"]
                cases.append(with_bed_compliance(case) if coupled else case)
    return cases


def lumping_cases(ankles: tuple[str, ...] = tuple(ANKLES), nus: tuple[float, ...] = NUS, options: dict[str, Any] | None = None) -> list[Case]:
    """The lumped FE (one layer of the summed thickness on the talus, the tibial bone rigid)
    against the two-layer FE (:func:`lumping_case_name`): the lumping error, signed (lumped - two
    layers) / two layers, both at ``options`` (default :data:`FE_ANKLES`, the beds' run). Reported (sanity bounds)."""
    options = dict(FE_ANKLES if options is None else options)
    return [fe_comparison_case(
        lumping_case_name(ankle, nu),
        f"{ANKLES[ankle][1]} standing, nu {nu:g}, {', '.join(f'{f:g}' for f in LOADS_N)} N: the FE of one layer of the summed thickness on the talus "
        f"(lumped) against the two-layer FE, at {options['mesh_size_mm']:g} mm",
        ANKLES[ankle][0], ("fe-lumped", "fe-two-layer"), overrides=ankle_overrides(ankle, nu), options=options,
        params={"poissons_ratio": nu}, maps=False)
        for nu in sorted(nus, reverse=True) for ankle in ankles]


def case_names() -> list[str]:
    """Every case of this campaign, DEM against the FE first (:func:`ankle_case_name`), then the
    lumping cases (:func:`lumping_case_name`)."""
    return [c.name for c in campaign().cases]


def campaign() -> Campaign:
    beds = ankle_cases()
    lumping = lumping_cases()
    default = tuple(c.name for c in beds if c.name.endswith(f"-{next(iter(BEDS))}"))
    analyses = (
        Analysis("goal", f"The default bed (coupled sandwich) against the two-layer FE at each load: goal {GOAL_REL:.0%} (displacement, regularised peak, area) "
                         f"where the FE's own error is below it; contact area at {LOADS_N[-1]:g} N at least {AREA_GROWTH:g}x its area at {LOADS_N[0]:g} N",
                 "per-load", default, {"quantities": GOAL_QUANTITIES, "reported": REPORTED_QUANTITIES + BED_COMPLIANCE_QUANTITIES, "goal": GOAL_REL,
                                       "area_growth": AREA_GROWTH}),
        Analysis("springs", "The independent springs against the two-layer FE at each load (beside the default bed; reported)", "per-load",
                 tuple(c.name for c in beds if c.name not in default), {"quantities": GOAL_QUANTITIES, "reported": REPORTED_QUANTITIES, "goal": None, "area_growth": AREA_GROWTH}),
        Analysis("lumping", "The lumping error on the ankles: one layer of the summed thickness on the talus (lumped FE) against the two-layer FE, "
                            "signed (lumped - two layers) / two layers, at each load", "per-load", tuple(c.name for c in lumping),
                 {"quantities": GOAL_QUANTITIES, "reported": REPORTED_QUANTITIES, "goal": None}),
        Analysis("table", "Every case over its loads (each error the worst of its loads)", "table", tuple(c.name for c in beds + lumping),
                 {"columns": FE_TABLE_COLUMNS}),
    )
    return Campaign(
        "ankles",
        "The built-in ankles on their cartilage (ideal and subject-like, standing, 333-2000 N, nu 0.3-0.49): DEM with the coupled sandwich and with the "
        "independent springs against the two-layer FE, the contact area against the load, and the lumping error (one layer of the summed thickness).",
        tuple(beds) + tuple(lumping),
        (),
        analyses,
    )
