"""The EDEM/DEM-vs-FE campaigns of issue 5 (cylinder-plane, subject, error-vs-runtime): their
definitions as data, the truth sides and the Pareto analysis. Nothing expensive runs here."""

from __future__ import annotations

import math

import pytest

from verification.analyses import ANALYSES, pareto_front, run_analysis
from verification.campaigns import METRICS, campaigns, describe_campaigns, get_campaign, validate_campaign
from verification.campaigns.cylinder_plane import SWEEP_LOADS_N, SWEEP_NUS, SWEEP_THICKNESS_MM
from verification.runner import side_key
from verification.sides import SIDES, TRUTH_STEPS, is_fe_side, resample_load, side_names

NEW = ("cylinder-plane", "subject", "error-vs-runtime")


@pytest.mark.parametrize("name", NEW)
def test_registered_and_valid(name):
    campaign = get_campaign(name)
    validate_campaign(campaign)
    assert name in campaigns()
    assert f"{name} ({len(campaign.cases)} cases, " in describe_campaigns(name)
    for case in campaign.cases:
        assert case.description and "\n" not in case.description
        assert set(case.tolerance) <= set(case.metrics) <= set(METRICS)
        assert all(side in side_names() for side in case.sides)
        assert all(isinstance(v, (int, float)) and not math.isnan(v) for v in case.tolerance.values())
    for figure in campaign.figures:
        assert set(figure.cases) <= {c.name for c in campaign.cases}
    assert all(a.kind in ANALYSES for a in campaign.analyses)


def test_cylinder_plane_sweeps_one_at_a_time():
    campaign = get_campaign("cylinder-plane")
    slab = [c for c in campaign.cases if c.sides == ("dem", "fe-slab")]
    layer = [c for c in campaign.cases if c.sides == ("dem", "fe-layer")]
    assert {c.scene for c in slab} == {"ideal-standing"} and {c.scene for c in layer} == {"cylinder-layer"}
    # one-at-a-time: every case differs from the base (333 N, nu 0.42, 2 mm) in one parameter at most
    for case in campaign.cases:
        p = case.params
        assert sum([p["load_n"] != 333.0, p["poissons_ratio"] != 0.42, p["thickness_mm"] != 2.0]) <= 1
        assert case.overrides["load.force_n"] == [0.0, 0.0, p["load_n"]]
        assert case.overrides["cartilage.poissons_ratio"] == p["poissons_ratio"]
        assert case.options == {"mesh_size_mm": 1.0, "degree": 2}  # coarse P2 (TH automatic from 0.49)
        assert case.tolerance["non_finite_outputs"] == 0.0 and case.tolerance["force_residual_rel"] <= 1e-6
    for cases in (slab, layer):
        assert {c.params["load_n"] for c in cases} == set(SWEEP_LOADS_N)
        assert {c.params["poissons_ratio"] for c in cases} == set(SWEEP_NUS)
    assert {c.params["thickness_mm"] for c in layer} == set(SWEEP_THICKNESS_MM)
    for case in layer:  # the layer and the plane's gap move together
        assert case.overrides["geometry.plafond_gap_mm"] == case.overrides["cartilage.thickness_mm"] == case.params["thickness_mm"]
    # every layer point twice, independent springs and coupled thin layer, sharing one FE run
    springs = [c for c in layer if "cartilage.coupling" not in c.overrides]
    coupled = {c.name: c for c in layer if c.overrides.get("cartilage.coupling") == "thin-layer"}
    assert len(springs) == len(coupled) == len(layer) // 2
    for case in springs:
        twin = coupled[case.name.replace("layer-", "layer-coupled-", 1)]
        assert twin.params == case.params and side_key(twin, 1) == side_key(case, 1)
    assert all(c.overrides["ligaments"] == [] for c in slab)
    sweeps = [f for f in campaign.figures if f.kind == "sweep"]
    assert {f.x for f in sweeps} == {"load_n", "poissons_ratio", "thickness_mm"} and len(sweeps) == 5


def test_subject_cases_drop_ligaments_and_fix_ty_at_toe_off():
    campaign = get_campaign("subject")
    assert {c.scene for c in campaign.cases} == {"subject-standing", "subject-toe-off"}
    # DEM and EDEM, springs and coupled: four cases per scene, one FE run
    for scene in ("subject-standing", "subject-toe-off"):
        mine = [c for c in campaign.cases if c.scene == scene]
        assert {(c.sides[0], c.overrides.get("cartilage.coupling", "none")) for c in mine} == {(m, k) for m in ("dem", "edem") for k in ("none", "thin-layer")}
        assert len({side_key(c, 1) for c in mine}) == 1
    for case in campaign.cases:
        assert case.sides[1] == "fe-slab" and case.overrides["ligaments"] == []
        assert "ligaments removed" in case.description
        if case.scene == "subject-toe-off":
            assert "ty" in case.overrides["constraints.fixed_dofs"] and "ty fixed" in case.description


def test_error_vs_runtime_families_and_truths():
    campaign = get_campaign("error-vs-runtime")
    families = {c.name.rsplit("-", 1)[0] for c in campaign.cases}
    assert families == {"dem", "dem-coupled", "fe-p1", "edem"}
    for case in campaign.cases:
        family = case.name.rsplit("-", 1)[0]
        assert case.sides[1] == ("edem-128-steps" if family == "edem" else "fe-slab-truth")
    assert [f.kind for f in campaign.figures].count("error-vs-time") == 1
    assert {a.kind for a in campaign.analyses} == {"pareto"}
    assert is_fe_side("fe-slab-truth") and not is_fe_side("edem-128-steps")
    assert {"fe-slab-truth", "edem-128-steps"} <= set(SIDES)
    # the truth ignores the spring mesh and the coupling: every case against it shares one run
    assert len({side_key(c, 1) for c in campaign.cases if c.sides[1] == "fe-slab-truth"}) == 1


def test_resample_load_keeps_the_history():
    overrides = {"ligaments": [], "load.time_s": [0.0, 0.5, 1.0], "load.force_n": [[0.0, 0.0, 0.0], [0.0, 0.0, 100.0], [0.0, 0.0, 333.0]]}
    out = resample_load(overrides, TRUTH_STEPS)
    assert len(out["load.time_s"]) == TRUTH_STEPS + 1 and out["ligaments"] == []
    assert out["load.time_s"][-1] == 1.0 and out["load.force_n"][-1] == [0.0, 0.0, 333.0]
    assert out["load.force_n"][64] == pytest.approx([0.0, 0.0, 100.0])


def test_pareto_front_and_analysis():
    assert pareto_front([(1.0, 0.5), (2.0, 0.1), (3.0, 0.2), (0.5, 1.0)]) == [True, True, False, True]
    campaign = get_campaign("error-vs-runtime")
    analysis = campaign.analyses[0]
    rows = {}
    for k, case in enumerate(campaign.cases):
        rows[case.name] = {
            "status": "ran",
            "metrics": {analysis.settings["metric"]: 1.0 / (k + 1)},
            "sides": [{"side": case.sides[0], "status": "ok", "wall_time_s": float(k + 1)}, {"side": case.sides[1], "status": "ok", "wall_time_s": 20.0}],
        }
    rows[campaign.cases[0].name]["metrics"][analysis.settings["metric"]] = 10.0  # dominated by none (fastest) still on the front
    rows[campaign.cases[1].name]["metrics"][analysis.settings["metric"]] = 100.0  # slower and worse than case 0: dominated
    result = run_analysis(analysis, rows)
    assert result["status"] == "reported"
    front = result["values"]["front"]
    assert campaign.cases[0].name in front and campaign.cases[1].name not in front
    assert campaign.cases[-1].name in front  # the most accurate
    # one front per truth: the best EDEM point is on its front whatever the FE-truth points do
    edem = [c.name for c in campaign.cases if c.sides[1] == "edem-128-steps"]
    assert edem[-1] in front and {v["truth"] for v in result["values"]["points"]} == {"fe-slab-truth", "edem-128-steps"}


def test_error_vs_time_figure_draws(tmp_path):
    pytest.importorskip("matplotlib")
    from dataclasses import asdict

    from reports.html import _error_time_figure

    campaign = get_campaign("error-vs-runtime")
    figure = next(f for f in campaign.figures if f.kind == "error-vs-time")
    rows = {
        c.name: {"metrics": {m: 0.1 / (k + 1) for m in figure.y}, "sides": [{"wall_time_s": 1.0 + k}, {"side": c.sides[1], "wall_time_s": 20.0}]}
        for k, c in enumerate(campaign.cases)
    }
    path = tmp_path / "f.png"
    _error_time_figure(asdict(figure), rows, path)
    assert path.stat().st_size > 0
