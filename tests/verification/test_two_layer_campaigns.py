"""The campaigns of two deformable layers (``two-layers``, ``ankles``) as data, and their analyses
(``per-load``, ``pairs``) on rows made by hand.

Invariants: the beds of a point share one FE run (the same side key: the FE never reads the bed)
and differ only in the bed's keys; every lumping case and its beds solve the same two-layer FE;
the ankles' loads are the three time points of one run; each study point of the two-layer FE is
in fe-convergence at the level its campaign uses. The analyses: a per-load error beyond the goal
is "outside" only where the FE's own error is below the goal, and the area growth is measured
from the smallest to the largest load.
"""

from __future__ import annotations

import json

import pytest

from verification.campaigns import get_campaign, validate_campaign
from verification.runner import side_key
from verification.sides import DEM_ONLY_OVERRIDES


def _without_bed(overrides: dict) -> dict:
    return {k: v for k, v in overrides.items() if k not in DEM_ONLY_OVERRIDES}


def test_two_layers_beds_and_the_lumping_case_of_a_point_share_one_two_layer_fe_run():
    from verification.campaigns.two_layers import BEDS, FE_LEVEL, NUS, SPLITS, bed_case_name, lumping_case_name

    campaign = get_campaign("two-layers")
    validate_campaign(campaign)
    by_name = {c.name: c for c in campaign.cases}
    assert len(campaign.cases) == len(SPLITS) * len(NUS) * (len(BEDS) + 1)
    for split, (mobile, fixed) in SPLITS.items():
        for nu in NUS:
            lumping = by_name[lumping_case_name(split, nu)]
            assert lumping.sides == ("fe-lumped", "fe-two-layer") and lumping.options == FE_LEVEL
            assert lumping.overrides["cartilage.mobile_thickness_mm"] == mobile and lumping.overrides["cartilage.fixed_thickness_mm"] == fixed
            for bed in BEDS:
                case = by_name[bed_case_name(bed, split, nu)]
                assert case.sides == ("dem", "fe-two-layer") and case.options == FE_LEVEL
                assert _without_bed(case.overrides) == lumping.overrides
                assert side_key(case, 1) == side_key(lumping, 1)
    # different points, different FE runs
    assert len({side_key(by_name[lumping_case_name(s, nu)], 1) for s in SPLITS for nu in NUS}) == len(SPLITS) * len(NUS)


def test_ankles_cases_load_the_ankle_three_times_in_one_run_and_share_it_between_beds():
    from verification.campaigns.ankles import ANKLES, BEDS, LOADS_N, NUS, ankle_case_name, case_names, lumping_case_name

    campaign = get_campaign("ankles")
    validate_campaign(campaign)
    assert case_names() == [c.name for c in campaign.cases]
    by_name = {c.name: c for c in campaign.cases}
    for ankle, (scene, _what) in ANKLES.items():
        for nu in NUS:
            cases = [by_name[ankle_case_name(ankle, bed, nu)] for bed in BEDS]
            lumping = by_name[lumping_case_name(ankle, nu)]
            for case in cases:
                assert case.scene == scene and case.sides == ("dem", "fe-two-layer")
                assert [f[2] for f in case.overrides["load.force_n"]] == list(LOADS_N) and case.overrides["ligaments"] == []
                assert _without_bed(case.overrides) == lumping.overrides
            assert len({side_key(c, 1) for c in [*cases, lumping]}) == 1
            # judged against the model band on the card's metrics
            assert {"displacement_rel_error", "contact_area_rel_error", "regularised_peak_pressure_rel_error"} <= {
                m for m, b in cases[0].basis.items() if b.kind == "model-band"}


def test_the_two_layer_fe_points_are_studied_at_the_level_their_campaign_uses():
    from verification.campaigns.fe_convergence import point_levels, reference_points
    from verification.fe_convergence import fe_key

    points = reference_points(set())
    studied = {fe_key(c.scene, c.sides[-1], dict(c.overrides), o) for _, c in points for o in point_levels(c)}
    for name, goal_nus in (("two-layers", (0.3, 0.45, 0.49, 0.499)), ("ankles", (0.3, 0.42, 0.49))):
        for case in get_campaign(name).cases:
            if case.sides[-1] != "fe-two-layer" or case.params["poissons_ratio"] not in goal_nus:
                continue
            assert fe_key(case.scene, case.sides[-1], dict(case.overrides), dict(case.options)) in studied, case.name


def _per_load_row(tmp_path, name: str, entries: list[dict]) -> dict:
    case_dir = tmp_path / "cases" / name
    case_dir.mkdir(parents=True)
    (case_dir / "metrics.json").write_text(json.dumps({"comparison": {"per_time": entries}}), encoding="utf-8")
    return {"name": name, "status": "ran", "sides": [], "metrics": {}, "params": {}, "out_dir": str(tmp_path), "case_dir": f"cases/{name}",
            "scene": "nowhere", "overrides": {}, "options": {}}


@pytest.mark.parametrize("fe_error, verdict", [(0.02, "outside: displacement"), (0.2, "not judged")])
def test_per_load_judges_each_load_only_where_the_fe_error_is_below_the_goal(tmp_path, monkeypatch, fe_error, verdict):
    import verification.fe_convergence as fc
    from verification.analyses import run_analysis
    from verification.campaign_model import Analysis

    monkeypatch.setattr(fc, "fe_relative_error", lambda row, reference=None: {"displacement_rel_error": fe_error, "contact_area_rel_error": fe_error})
    entries = [{"load_n": load, "contact_area_a_mm2": area_a, "contact_area_b_mm2": area_b, "displacement_rel_error": du, "contact_area_rel_error": 0.01}
               for load, area_a, area_b, du in ((333.0, 400.0, 360.0, 0.05), (2000.0, 610.0, 540.0, -0.12))]
    rows = {"c": _per_load_row(tmp_path, "c", entries)}
    analysis = Analysis("g", "t", "per-load", ("c",), {"quantities": (("displacement", "displacement_rel_error"), ("contact area", "contact_area_rel_error")),
                                                        "goal": 0.10, "area_growth": 1.25})
    result = run_analysis(analysis, rows)
    verdicts = [v["verdict"] for v in result["values"]["rows"]]
    assert verdicts[0] == ("within" if fe_error < 0.10 else "not judged (FE error unknown or >= goal): displacement, contact area")
    assert verdicts[1].startswith(verdict)
    # growth 610 / 400 = 1.52 (a) and 540 / 360 = 1.5 (b): both at least 1.25
    assert "1.52 (a), 1.50 (b, the FE): at least 1.25x for both" in " ".join(result["notes"])
    assert result["status"] == ("flagged" if verdict.startswith("outside") else "reported")


def test_pairs_gives_the_signed_difference_of_two_cases():
    from verification.analyses import run_analysis
    from verification.campaign_model import Analysis

    rows = {n: {"name": n, "status": "ran", "sides": [], "metrics": {"b_displacement_norm_mm": v}} for n, v in (("two", 0.45), ("rigid", 0.5))}
    analysis = Analysis("p", "t", "pairs", ("two", "rigid"), {"pairs": (("500 N", "two", "rigid"),),
                                                            "quantities": (("displacement", "b_displacement_norm_mm", "b_displacement_norm_mm"),)})
    entry = run_analysis(analysis, rows)["values"]["rows"][0]
    assert entry["difference"] == pytest.approx((0.45 - 0.5) / 0.5, rel=1e-15)
