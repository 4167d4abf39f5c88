"""The campaign registry (docs/campaigns.md, docs/method.md#7-comparison-metrics): one module per campaign, registered here by hand.

Each module of this package defines ``campaign()``, returning its :class:`Campaign`. To add a
campaign: write ``verification/campaigns/<name>.py`` with ``campaign()`` and add the module to
:data:`CAMPAIGN_MODULES`. The data model (cases, figures, analyses) is
:mod:`verification.campaign_model`; the sides a case may run are :data:`verification.sides.SIDES`
and the analysis kinds :data:`verification.analyses.ANALYSES`.

Campaigns: ``edem-analytic`` (EDEM/DEM against closed forms), ``stability`` (stiff and extreme
input, each ending in its declared outcome, no NaN anywhere), ``fe-analytic`` (the FE reference
against Hertz line contact and confined compression on three meshes each, with observed orders),
``fe-two-layers`` (the FE of two deformable layers against Hertz of two elastic cylinders and two
confined layers in series, three meshes each, with observed orders),
``stance`` (EDEM vs DEM over the built-in stance scenes, the thesis's figures beside ours, DEM
vs the FE slab at five instants), ``sensitivity`` (h_max x ligament modulus, 20 x 20 EDEM
stances, the thesis's fig. 4.3.10), ``quick`` (a subset for CI), and EDEM/DEM against the FE
reference: ``cylinder-plane``, ``subject``, ``error-vs-runtime``; ``thin-layer`` (the coupled
thin-layer bed and the independent springs against the FE); ``two-layers`` (two cartilage
layers on a cylinder: the lumping error, the beds against the two-layer FE); ``ankles`` (the
built-in ankles on their cartilage against the two-layer FE, 333-2000 N); ``viscoelastic`` (viscoelastic EDEM
against the Kelvin-Voigt FE twin over time); ``fe-convergence`` (the FE reference's own
mesh-convergence error at quick's FE points); ``population`` (1000 seeded subject-like ankles
over the stance, EDEM), ``population-coupled`` (the same on the coupled thin layer);
``real-knee`` (DEM against the FE on the public Lenhart MRI knee, given with ``--data``:
:data:`DATA_CAMPAIGNS`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from geometries.errors import InputError
from verification.campaign_model import (
    METRICS,
    SCENES_DIR,
    Analysis,
    Campaign,
    Case,
    Expect,
    Figure,
    ramp_overrides,
    validate_campaign,
)
from verification.campaigns import (
    ankles,
    cylinder_plane,
    edem_analytic,
    error_vs_runtime,
    fe_analytic,
    fe_convergence,
    fe_two_layers,
    population,
    population_coupled,
    quick,
    real_knee,
    sensitivity,
    stability,
    stance,
    subject,
    thin_layer,
    two_layers,
    viscoelastic,
)
from verification.campaigns.fe_analytic import CONFINED_SIZES_MM, HERTZ_SIZES_MM
from verification.campaigns.sensitivity import SENSITIVITY_HMAX_MM, SENSITIVITY_MODULUS_MPA
from verification.campaigns.sensitivity import campaign as sensitivity_campaign
from verification.campaigns.stance import (
    STANCE_INSTANTS,
    STANCE_SCENES,
    THESIS_STANCE,
    fe_instant_case_name,
    instant_indices,
    scene_instants,
)

#: the registered campaign modules, in the order `edem verify --list` shows them
CAMPAIGN_MODULES = (edem_analytic, stability, fe_analytic, fe_two_layers, stance, sensitivity, quick, cylinder_plane, subject, error_vs_runtime, thin_layer, two_layers,
                    ankles, viscoelastic, fe_convergence, population, population_coupled, real_knee)
#: campaigns on data the user gives (``edem verify NAME --data FOLDER``): name -> their module, whose
#: ``data_files(data)`` refuses (InputError naming --data or the missing file) a folder without them and
#: ``with_data(data, work dir)`` builds the campaign on it
DATA_CAMPAIGNS = {"real-knee": real_knee}


def campaigns() -> dict[str, Campaign]:
    """Every campaign by name, with the expected run time its module measured (``EXPECTED_TIME_S``)."""
    built = (dataclasses.replace(module.campaign(), expected_time_s=getattr(module, "EXPECTED_TIME_S", None)) for module in CAMPAIGN_MODULES)
    return {campaign.name: campaign for campaign in built}


def get_campaign(name: str, data: str | None = None, work: Path | None = None) -> Campaign:
    """The named campaign, or InputError listing the known ones. A campaign of
    :data:`DATA_CAMPAIGNS` is built on ``data`` (its inputs prepared in ``work``) and refused
    without it; ``data`` for another campaign is refused."""
    known = campaigns()
    if name not in known:
        raise InputError(f"unknown campaign '{name}'", key="CAMPAIGN", expected="one of " + ", ".join(known) + " (edem verify --list)")
    if name in DATA_CAMPAIGNS:
        return dataclasses.replace(DATA_CAMPAIGNS[name].with_data(data, work), expected_time_s=known[name].expected_time_s)
    if data is not None:
        raise InputError(f"campaign '{name}' takes no data folder", key="--data", expected="--data only with " + ", ".join(DATA_CAMPAIGNS))
    return known[name]


def expected_time_text(seconds: float | None) -> str:
    """"~40 s", "~11 min", "~1.5 h" or "time not measured"."""
    if seconds is None:
        return "time not measured"
    if seconds < 90:
        return f"~{seconds:.0f} s"
    if seconds < 5400:
        return f"~{seconds / 60:.0f} min"
    return f"~{seconds / 3600:.1f} h"


def describe_campaigns(name: str | None = None) -> str:
    """What `edem verify --list` prints: one line per campaign (cases, expected time on 2 cores,
    what it is), or with ``name`` the cases of that campaign, one line each."""
    if name is None:
        known = campaigns().values()
        width = max(len(c.name) for c in known)
        lines = [f"{c.name:{width}s} {len(c.cases):4d} cases  {expected_time_text(c.expected_time_s):>18s}  {c.description}" for c in known]
        lines.append("(expected wall time with 2 jobs on 2 cores, nothing cached; `edem verify --list CAMPAIGN` lists its cases)")
        return "\n".join(lines) + "\n"
    known = campaigns()
    campaign = known[name] if name in known else get_campaign(name)  # (a data campaign: its cases, listed without the data)
    lines = [f"{campaign.name} ({len(campaign.cases)} cases, {expected_time_text(campaign.expected_time_s)} on 2 cores): {campaign.description}"]
    for case in campaign.cases:
        lines.append(f"  {case.name:32s} [{' vs '.join(case.sides)}] {case.description}")
    return "\n".join(lines) + "\n"


__all__ = [
    "CAMPAIGN_MODULES", "CONFINED_SIZES_MM", "DATA_CAMPAIGNS", "HERTZ_SIZES_MM", "METRICS", "SCENES_DIR", "SENSITIVITY_HMAX_MM",
    "SENSITIVITY_MODULUS_MPA", "STANCE_INSTANTS", "STANCE_SCENES", "THESIS_STANCE", "Analysis", "Campaign", "Case",
    "Expect", "Figure", "campaigns", "describe_campaigns", "fe_instant_case_name", "get_campaign", "instant_indices",
    "ramp_overrides", "scene_instants", "sensitivity_campaign", "validate_campaign",
]
