"""``quick``: a CI subset of the other campaigns (well under 5 minutes on 2 cores)."""

from __future__ import annotations

from verification.campaign_model import Campaign, Case, uniform_tolerance
from verification.campaigns.edem_analytic import _analytic_cases, _analytic_figures
from verification.campaigns.fe_analytic import CONFINED_SIZES_MM, _fe_analytic_cases
from verification.campaigns.stability import _stability_cases
from verification.metrics import SPEC8_METRICS


def _ideal_standing_case() -> Case:
    return Case(
        "ideal-standing-edem-vs-dem",
        "ideal standing (333 N): EDEM's first step starts from the initial pose, so it equals DEM",
        "ideal-standing",
        ("edem", "dem"),
        SPEC8_METRICS,
        uniform_tolerance(1e-9),
        maps=True,
    )



def campaign() -> Campaign:
    stability = {c.name: c for c in _stability_cases()}
    picks = ["nu-0.4999", "load-0", "pull-apart", "tangential-no-shear", "interpenetrating-start", "cylinder-axial-no-shear", "ve-exact-tau1e-04-dt1e+00", "ve-rk2-tau1e-04-dt1e+00"]
    fe = {c.name: c for c in _fe_analytic_cases()}
    # one cheap FE case (a second or two; "unavailable" without dolfinx): the coarsest confined slab
    fe_picks = [f"fe-confined-compression-h{max(CONFINED_SIZES_MM):g}"]
    return Campaign(
        "quick",
        "A CI subset (well under 5 minutes on 2 cores): every closed-form case, a few stability cases, ideal standing EDEM vs DEM, one cheap FE case (confined compression, coarse).",
        tuple(_analytic_cases()) + tuple(stability[n] for n in picks) + (_ideal_standing_case(),) + tuple(fe[n] for n in fe_picks),
        _analytic_figures(),
    )
