"""``quick``: the main job (``make demo``), well under 5 minutes on 2 cores.

It opens with the ankle answer: DEM against the FE reference on the ideal ankle standing (and the
subject-like ankle), where they agree and where the independent-spring bed breaks (Poisson's
ratio, cartilage thickness, low loads, the rim of the contact patch), judged against a declared
model band (:data:`MODEL_BAND_REL`). Then every closed-form case, a few stability cases, ideal
standing EDEM vs DEM and one cheap FE verification case. The FE here is coarse (P2 at 1.0 mm,
Taylor-Hood from nu = 0.49) to keep the job short; ``cylinder-plane`` and ``subject`` have the
full sweeps.
"""

from __future__ import annotations

import dataclasses

from verification.campaign_model import Analysis, Campaign, Case, Figure, uniform_basis, uniform_tolerance
from verification.campaigns.cylinder_plane import campaign as cylinder_plane_campaign
from verification.campaigns.edem_analytic import _analytic_cases, _analytic_figures
from verification.campaigns.fe_analytic import CONFINED_SIZES_MM, _fe_analytic_cases
from verification.campaigns.stability import _stability_cases
from verification.campaigns.subject import campaign as subject_campaign
from verification.campaigns.viscoelastic import campaign as viscoelastic_campaign
from verification.metrics import COMPARISON_METRICS
from verification.verdicts import INVARIANT, MODEL_BAND, MODEL_BAND_REASON, MODEL_BAND_REL, Basis

BAND_METRICS = ("peak_pressure_rel_error", "contact_area_rel_error")
BAND_BASIS = Basis(MODEL_BAND, MODEL_BAND_REASON)
TRUST_NUS = (0.0, 0.3, 0.42, 0.45, 0.49)
TRUST_THICKNESS_MM = (1.0, 2.0, 3.0)
TRUST_LOW_LOAD_N = 100.0
TRUST_FIGURE = "trust-error-vs-nu"
#: the cheapest FE that is still a reference: P1 at 1.0 mm (10 k DOFs, within 2.5 % of P2 at 0.7 mm
#: on the ideal ankle at nu 0.42, fem_reference.scene_run) where P1 does not lock (nu <= 0.42);
#: P2 / Taylor-Hood at 1.0 mm above, and for the thin layers
FE_P1 = {"mesh_size_mm": 1.0, "degree": 1}

#: wall time with 2 jobs on 2 cores, nothing cached: measured 220 s on the shared 2-core machine at
#: load 4-8 (120 s of CPU time), 285-333 s at load 8-10; the Taylor-Hood case at nu = 0.49 is the
#: longest single case; plus the viscoelastic case (its FE run, 7 time points of P1, measured 37 s
#: at load 2-7; not timed within quick)
EXPECTED_TIME_S = 260.0


#: the viscoelastic campaign's cheapest case (verification.campaigns.viscoelastic)
VISCOELASTIC_CASE = "slab-step-dt2-coupled-nu0.42"


def _banded(case: Case) -> Case:
    """A DEM-vs-FE case judged against the model band on peak pressure and contact area; its other
    errors reported (sanity bounds only)."""
    tolerance = {**case.tolerance, **{m: MODEL_BAND_REL for m in BAND_METRICS}}
    description = case.description.replace("Generous tolerances (measured, not judged)", "").replace(". Generous tolerances", "").rstrip(" ;.")
    description += f"; peak pressure and contact area judged against the declared +-{MODEL_BAND_REL:.0%} model band, the rest reported"
    return dataclasses.replace(case, tolerance=tolerance, basis={**case.basis, **{m: BAND_BASIS for m in BAND_METRICS}}, description=description)


def trust_cases() -> list[Case]:
    """DEM vs the FE reference: the ideal ankle over Poisson's ratio, the layer over thickness and
    at a low load, the subject-like ankle standing."""
    cp = {c.name: c for c in cylinder_plane_campaign().cases}
    names = [f"slab-F333-nu{nu:g}" for nu in sorted(TRUST_NUS, reverse=True)]  # the slowest FE (highest nu) starts first
    names += [f"layer-F333-nu0.42-t{t:g}" for t in TRUST_THICKNESS_MM] + [f"layer-F{TRUST_LOW_LOAD_N:g}-nu0.42-t2"]
    cases = []
    for n in names:
        case = cp[n]
        p1 = n.startswith("slab") and case.params["poissons_ratio"] <= 0.42
        description = case.description.replace("FE P2 at 1.0 mm", "FE P1 at 1.0 mm") if p1 else case.description
        cases.append(_banded(dataclasses.replace(case, maps=n == "slab-F333-nu0.42", options=dict(FE_P1) if p1 else case.options, description=description)))
    sub = {c.name: c for c in subject_campaign().cases}
    standing = sub["subject-standing-dem-vs-fe"]
    cases.append(_banded(dataclasses.replace(standing, options=dict(FE_P1), description=standing.description.replace("(P2, 1.0 mm)", "(P1, 1.0 mm)"))))
    return cases


def _ideal_standing_case() -> Case:
    return Case(
        "ideal-standing-edem-vs-dem",
        "ideal standing (333 N): EDEM's first step starts from the initial pose, so it equals DEM (an identity, not an accuracy check)",
        "ideal-standing",
        ("edem", "dem"),
        COMPARISON_METRICS,
        uniform_tolerance(1e-9),
        maps=True,
        basis=uniform_basis(INVARIANT, "EDEM's first step from the initial pose is DEM by construction: identical to round-off"),
    )


def _trust_analysis() -> Analysis:
    nus = tuple(f"slab-F333-nu{nu:g}" for nu in TRUST_NUS)
    layers = tuple(f"layer-F333-nu0.42-t{t:g}" for t in TRUST_THICKNESS_MM)
    low = f"layer-F{TRUST_LOW_LOAD_N:g}-nu0.42-t2"
    return Analysis(
        "trust",
        "Can I trust it for my ankle? DEM against the FE reference",
        "trust",
        nus + layers + (low, "subject-standing-dem-vs-fe"),
        {
            "base": "slab-F333-nu0.42",
            "nu_cases": list(nus),
            "layer_cases": list(layers),
            "layer_base": "layer-F333-nu0.42-t2",
            "low_load": low,
            "subject": "subject-standing-dem-vs-fe",
            "band": MODEL_BAND_REL,
            "figure": TRUST_FIGURE,
            "fe_note": "The FE reference here is coarse so that this job stays short on 2 cores: P1 elements at 1.0 mm for the ideal and subject ankles up to nu = 0.42 "
                       "(within 2.5 % of P2 at 0.7 mm on the ideal ankle), P2 at 1.0 mm at nu = 0.45 and for the layers (within 0.7 %), Taylor-Hood P2-P1 at nu = 0.49. "
                       "The cylinder-plane and subject campaigns run P2 throughout and the full sweeps (nu up to 0.499, loads up to 4190 N, toe-off).",
        },
    )


def campaign() -> Campaign:
    stability = {c.name: c for c in _stability_cases()}
    picks = ["nu-0.4999", "load-0", "pull-apart", "tangential-no-shear", "interpenetrating-start", "cylinder-axial-no-shear", "ve-exact-tau1e-04-dt1e+00", "ve-rk2-tau1e-04-dt1e+00"]
    fe = {c.name: c for c in _fe_analytic_cases()}
    # one cheap FE case (a second or two; "unavailable" without dolfinx): the coarsest confined slab
    fe_picks = [f"fe-confined-compression-h{max(CONFINED_SIZES_MM):g}"]
    trust = trust_cases()
    # one cheap viscoelastic case: coupled EDEM against the Kelvin-Voigt FE twin over a step (7 time points, FE P1)
    viscous = viscoelastic_campaign().case(VISCOELASTIC_CASE)
    figure = Figure(TRUST_FIGURE, "DEM against the FE slab on the ideal ankle (333 N): relative errors against Poisson's ratio", "lines",
                    tuple(f"slab-F333-nu{nu:g}" for nu in TRUST_NUS), x="poissons_ratio",
                    y=("peak_pressure_rel_error", "contact_area_rel_error", "displacement_rel_error", "pressure_l2_rel_error"), exact={"band": MODEL_BAND_REL})
    return Campaign(
        "quick",
        "The main job: first the ankle answer (DEM against the FE reference on the ideal and subject-like ankles: where it agrees, where it breaks), then every "
        "closed-form case, a few stability cases, ideal standing EDEM vs DEM, one cheap FE verification case (confined compression, coarse) "
        "and one viscoelastic case (coupled EDEM against the Kelvin-Voigt FE twin over a step held 3 tau).",
        tuple(trust) + tuple(_analytic_cases()) + tuple(stability[n] for n in picks) + (_ideal_standing_case(),) + tuple(fe[n] for n in fe_picks) + (viscous,),
        (figure,) + _analytic_figures(),
        (_trust_analysis(),),
    )
