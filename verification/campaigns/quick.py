"""``quick``: the main job (``make demo``; :data:`EXPECTED_TIME_S`: its wall time measured on the shared machine).

It opens with the ankle answer: the built-in ankles on their cartilage (``ideal-standing`` and
``subject-standing``: talar and tibial layers tapered to their margins, the gap law), DEM with the
scenes' default bed (the coupled layer, the two layers as a sandwich) beside the independent
springs, against their FE twin (``fe-two-layer``: both layers deformable) at 333, 1000 and 2000 N
(three time points of one run) and Poisson's ratio :data:`ANSWER_NUS`: the cases of the ``ankles``
campaign (:func:`verification.campaigns.ankles.ankle_cases`) on this job's FE
(:data:`FE_ANSWER`). Each of the design card's three quantities (displacement, regularised peak
pressure, contact area; and the pressure field) is judged against the declared model band
(:data:`verification.verdicts.MODEL_BAND_REL`) at every load; the contact area is an outcome of the
anatomy here, nothing is set by construction. One row of its own keeps the thesis's threshold law
(:data:`THRESHOLD_CASE`: the thesis's ankle geometry and bed against the FE slab), its contact area
marked as set by h_max. Then the layer over thickness and at a low load, every closed-form case, a
few stability cases, ideal standing EDEM vs DEM, one cheap FE verification case and one
viscoelastic case. ``ankles``, ``cylinder-plane``, ``subject`` and ``thin-layer`` have the full
sweeps.
"""

from __future__ import annotations

import dataclasses

from edem.beds import BEDS as BED_CLASSES
from verification.campaign_model import THESIS_BED, Analysis, Campaign, Case, Figure, uniform_basis, uniform_tolerance
from verification.campaigns.ankles import ANKLES, AREA_GROWTH, LOADS_N, ankle_case_name, ankle_cases
from verification.campaigns.ankles import BEDS as ANKLE_BEDS
from verification.campaigns.cylinder_plane import campaign as cylinder_plane_campaign
from verification.campaigns.edem_analytic import _analytic_cases, _analytic_figures
from verification.campaigns.fe_analytic import CONFINED_SIZES_MM, _fe_analytic_cases
from verification.campaigns.stability import _stability_cases
from verification.campaigns.viscoelastic import campaign as viscoelastic_campaign
from verification.fe_comparison import banded
from verification.metrics import COMPARISON_METRICS
from verification.verdicts import BY_CONSTRUCTION, INVARIANT, MODEL_BAND_REL, Basis

#: the ankle answer's Poisson's ratio: the built-in scenes' own. One value: the two-layer FE of one
#: ankle and nu (three loads) costs 218 s of CPU time on the ideal ankle at P2 2.0 mm (measured
#: 2026-11-28), so a second nu would take the job past 10 minutes; ``ankles`` sweeps 0.3-0.49
ANSWER_NUS = (0.42,)
#: the ankle answer's FE: P2 at 2.0 mm, the coarsest level of the ``fe-convergence`` study (M's own
#: 0.96 mm triangles, two elements through each layer; 118 k DOFs on the ideal ankle). Its own
#: error is the study's (:func:`verification.fe_convergence.fe_relative_error`; measured 2026-11-28:
#: regularised peak 0.54-0.59 %, area 1.39-1.74 %, displacement 0.25 % subject-like and 4.31 % ideal
#: at 333 N). The next level below 3 % on every card metric is 0.7 mm: 1368 s of wall time for the
#: ideal ankle's FE alone against 190 s here (docs/campaigns.md#quick-the-main-job-make-demo)
FE_ANSWER = {"mesh_size_mm": 2.0, "degree": 2}
#: the ankles' beds in the answer (keys of verification.campaigns.ankles.BEDS), the scenes' default first
ANSWER_BEDS = tuple(ANKLE_BEDS)
#: the thesis's threshold law, one row: the ideal ankle on the thesis's geometry (no cartilage
#: layers), independent springs, against the FE slab at 333 N and nu 0.42 (cylinder-plane's case
#: on this job's FE)
THRESHOLD_CASE = "slab-F333-nu0.42"
#: the threshold law's contact area on an ankle is its candidate springs' area (463 mm^2 on the
#: ideal ankle at every load and nu, whatever the bed): set by h_max, and judged against the
#: model band all the same ("verified" needs every card metric inside its band; verification.verdicts)
THRESHOLD_AREA_BASIS = Basis(BY_CONSTRUCTION, f"declared band of agreement between two models, +-{MODEL_BAND_REL:.0%}, for an area set by h_max, by construction: the threshold "
                                              "law puts every candidate spring (within h_max of F) in contact on the ankles, so its contact area is the "
                                              "candidates' area (463 mm^2 on the ideal ankle) at every load and Poisson's ratio; no bed moves it, and "
                                              "verified needs it inside the band")
#: the default bed's goal: displacement, regularised peak and area within 10 % of the FE at every load (reported, not judged)
TRUST_GOAL_REL = 0.10
TRUST_THICKNESS_MM = (1.0, 2.0, 3.0)
TRUST_LOW_LOAD_N = 100.0
#: the threshold row's FE: P1 at 1.0 mm (10 k DOFs, a few seconds; within 2.5 % of P2 at 0.7 mm on
#: the ideal ankle's slab at nu 0.42, fe-convergence's P1 column)
FE_P1 = {"mesh_size_mm": 1.0, "degree": 1}

#: wall time with 2 jobs on 2 cores, nothing cached: measured 140 s from a fresh clone on the idle
#: machine on 2026-11-28 (290 s of CPU time; FE on the Krylov path), 874 s earlier that day at load
#: 4-8; the ideal ankle's two-layer FE is the longest case (docs/campaigns.md#quick-the-main-job-make-demo)
EXPECTED_TIME_S = 140.0


#: the viscoelastic campaign's cheapest case (verification.campaigns.viscoelastic)
VISCOELASTIC_CASE = "slab-step-dt2-coupled-nu0.42"


def bed_label(case: Case) -> str:
    """The bed of ``case`` as the reports name it (edem.beds: "independent springs", "coupled layer")."""
    return BED_CLASSES[case.overrides["cartilage.coupling"]].label


def answer_cases() -> list[Case]:
    """The ankle answer: each bed of :data:`ANSWER_BEDS` against the two-layer FE on each ankle at
    each nu of :data:`ANSWER_NUS` (the ``ankles`` campaign's cases on :data:`FE_ANSWER`; the beds of
    an ankle and nu share one FE run)."""
    return ankle_cases(tuple(ANKLES), ANSWER_BEDS, ANSWER_NUS, FE_ANSWER)


def threshold_case() -> Case:
    """The thesis's threshold law, one row: cylinder-plane's ``slab-F333-nu0.42`` (the thesis's
    ankle, independent springs, the FE slab) on the P1 FE, its area marked as set by h_max."""
    template = {c.name: c for c in cylinder_plane_campaign().cases}[THRESHOLD_CASE]
    description = ("the thesis's threshold law on its ideal ankle (no cartilage layers), independent springs (the thesis's bed): DEM vs the FE slab "
                   "(333 N, nu 0.42, no ligaments); FE P1 at 1.0 mm. Its contact area is set by h_max (every candidate spring carries load)")
    return banded(dataclasses.replace(template, overrides={**template.overrides, **THESIS_BED}, options=dict(FE_P1), description=description, maps=False),
                  THRESHOLD_AREA_BASIS)


def layer_case_names() -> list[str]:
    """The bonded layer's cases (cylinder-plane's): over thickness at 333 N, then at a low load."""
    return [f"layer-F333-nu0.42-t{t:g}" for t in TRUST_THICKNESS_MM] + [f"layer-F{TRUST_LOW_LOAD_N:g}-nu0.42-t2"]


def trust_cases() -> list[Case]:
    """DEM against the FE: the ankle answer (:func:`answer_cases`), the threshold law's row
    (:func:`threshold_case`), the layer over thickness and at a low load (independent springs,
    gap law)."""
    cp = {c.name: c for c in cylinder_plane_campaign().cases}
    return answer_cases() + [threshold_case()] + [banded(cp[n]) for n in layer_case_names()]


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


#: the card metrics charted against the load, one panel each
ANSWER_ERRORS = ("displacement_rel_error", "regularised_peak_pressure_rel_error", "contact_area_rel_error")


def _answer_series() -> tuple[tuple[str, tuple[str, ...]], ...]:
    """(label, (case,)) per ankle and bed of the answer at each nu: "ideal ankle, coupled layer"..."""
    cases = {c.name: c for c in answer_cases()}
    several = len(ANSWER_NUS) > 1
    return tuple((f"{ANKLES[ankle][1]}, {bed_label(cases[name])}" + (f", nu {nu:g}" if several else ""), (name,))
                 for nu in ANSWER_NUS for ankle in ANKLES for bed in ANSWER_BEDS for name in [ankle_case_name(ankle, bed, nu)])


def _trust_figures() -> tuple[Figure, ...]:
    """The contact area against the load (DEM and FE) and the card metrics' signed errors against the load."""
    series = _answer_series()
    cases = tuple(n for _label, group in series for n in group)
    loads = ", ".join(f"{f:g}" for f in LOADS_N)
    return (
        Figure("ankle-area-vs-load", f"Contact area against load ({loads} N): DEM (solid) and the two-layer FE (dashed)", "area-vs-load", cases, series=series),
        Figure("ankle-errors-vs-load", "Signed error (DEM - FE) / |FE| against load; black bars: the model band", "per-load", cases, y=ANSWER_ERRORS, series=series),
    )


def _trust_analysis() -> Analysis:
    answer = answer_cases()
    cases = {c.name: c for c in answer}
    by_ankle = {ANKLES[ankle][1]: {bed_label(cases[ankle_case_name(ankle, bed, ANSWER_NUS[0])]): [ankle_case_name(ankle, bed, nu) for nu in ANSWER_NUS]
                                   for bed in ANSWER_BEDS} for ankle in ANKLES}
    layers = layer_case_names()
    return Analysis(
        "trust",
        "Can I trust it for my ankle? DEM against the FE on the cartilage ankles",
        "trust",
        tuple(c.name for c in answer) + (THRESHOLD_CASE,) + tuple(layers),
        {
            "ankles": by_ankle,
            "threshold": THRESHOLD_CASE,
            "layer_cases": layers[:-1],
            "layer_base": "layer-F333-nu0.42-t2",
            "low_load": layers[-1],
            "band": MODEL_BAND_REL,
            "goal": TRUST_GOAL_REL,
            "area_growth": AREA_GROWTH,
            "figures": [f.name for f in _trust_figures()],
            "fe_note": f"The FE of the ankle answer is the two-layer model (both cartilage layers deformable, each bonded to its bone) at P2 "
                       f"{FE_ANSWER['mesh_size_mm']:g} mm (the coarsest level of fe-convergence: M's own triangles, two elements through each layer), "
                       f"nu {', '.join(f'{nu:g}' for nu in ANSWER_NUS)} only, so that this job stays short on 2 cores; the ankles campaign has nu 0.3-0.49 at 1.0 mm. "
                       "The threshold law's row runs the FE slab at P1 1.0 mm (within 2.5 % of P2 at 0.7 mm), the layers P2 at 1.0 mm.",
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
    return Campaign(
        "quick",
        "The main job: first the ankle answer (the ideal and subject-like ankles on their cartilage at 333, 1000 and 2000 N: DEM with the default bed, the coupled "
        "layer, and with the independent springs against the two-layer FE; the thesis's threshold law in one row of its own), then every "
        "closed-form case, a few stability cases, ideal standing EDEM vs DEM, one cheap FE verification case (confined compression, coarse) "
        "and one viscoelastic case (coupled EDEM against the Kelvin-Voigt FE twin over a step held 3 tau).",
        tuple(trust) + tuple(_analytic_cases()) + tuple(stability[n] for n in picks) + (_ideal_standing_case(),) + tuple(fe[n] for n in fe_picks) + (viscous,),
        _trust_figures() + _analytic_figures(),
        (_trust_analysis(),),
    )
