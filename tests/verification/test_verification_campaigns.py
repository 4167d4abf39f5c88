"""Campaign definitions (data) and the campaigns themselves: every case ends in its declared
outcome / within its tolerance; `edem verify --list` shows one line per case."""

from __future__ import annotations

import pytest

from edem.cli import main
from geometries.errors import InputError
from verification.campaigns import METRICS, campaigns, describe_campaigns, get_campaign, validate_campaign
from verification.campaigns.quick import VISCOELASTIC_CASE
from verification.runner import run_campaign
from edem.scene import load_scene
from verification.campaign_model import THESIS_BED
from verification.campaigns.ankles import ANKLES, LOADS_N, ankle_case_name
from verification.campaigns.ankles import BEDS as ANKLE_BEDS
from verification.campaigns.quick import ANSWER_BEDS, ANSWER_NUS, FE_ANSWER, THRESHOLD_CASE, answer_cases, bed_label
from verification.sides import is_shared_side, side_inputs, side_names
from verification.verdicts import MODEL_BAND_REL


def test_every_campaign_is_valid_data():
    for campaign in campaigns().values():
        validate_campaign(campaign)
        for case in campaign.cases:
            assert case.description and "\n" not in case.description
            assert set(case.tolerance) <= set(case.metrics) <= set(METRICS)
            assert all(side in side_names() for side in case.sides)


def test_stability_cases_declare_outcomes_and_cover_the_extremes():
    stability = get_campaign("stability")
    assert all(case.expect is not None for case in stability.cases)
    overrides = [case.overrides for case in stability.cases]
    assert {o.get("cartilage.poissons_ratio") for o in overrides} >= {0.4999}
    assert {o.get("cartilage.youngs_modulus_mpa") for o in overrides} >= {0.01, 1e4}
    # loads that push the linear springs past their length (d = 2.8 mm > h = 2 mm) converge *with a
    # warning*; beyond the 3.5 mm ray window (d = 19 mm, 3 m) they are refused
    assert stability.case("load-15000").expect.warning
    assert all(stability.case(n).expect.outcome == "refused" and "ray window" in stability.case(n).expect.message for n in ("load-100000", "E-0.01"))
    assert not stability.case("load-1e-06").expect.warning
    taus = {o.get("viscoelastic.relaxation_time_s") for o in overrides}
    assert {1e-4, 1e4} <= taus
    rk2_refusals = [c for c in stability.cases if c.expect.outcome == "refused" and c.overrides.get("viscoelastic.integrator") == "rk2"]
    for case in rk2_refusals:  # refused exactly where dt > 2 tau
        dt = case.overrides["load.time_s"][1]
        assert dt > 2 * case.overrides["viscoelastic.relaxation_time_s"]


def test_quick_is_a_subset_of_the_other_campaigns_plus_ideal_standing():
    """quick's cases are other campaigns' cases: the ankle answer the ankles campaign's (on a coarser
    FE), the threshold law's row and the layers cylinder-plane's (the same runs, every card metric
    judged against the model band), the rest as they are."""
    known = {c.name: c for name in ("edem-analytic", "stability", "fe-analytic", "cylinder-plane", "viscoelastic") for c in get_campaign(name).cases}
    ankles = {c.name: c for c in get_campaign("ankles").cases}
    quick = get_campaign("quick")
    # the design card's three quantities: pressure (regularised peak and field), area, displacement
    banded = {"regularised_peak_pressure_rel_error", "pressure_l2_rel_error", "contact_area_rel_error", "displacement_rel_error"}
    answer = {c.name for c in answer_cases()}
    for case in quick.cases:
        if case.name == "ideal-standing-edem-vs-dem":
            continue
        if case.name in answer:
            twin = ankles[case.name]
            assert (case.scene, case.sides, case.overrides) == (twin.scene, twin.sides, twin.overrides)
            assert case.options == FE_ANSWER and case.params["poissons_ratio"] in ANSWER_NUS
            assert {m for m, b in case.bases().items() if b.kind == "model-band"} == banded  # nothing set by construction
            continue
        twin = known[case.name]
        if case.name == VISCOELASTIC_CASE:
            assert twin == case  # the viscoelastic campaign's case as it is
        elif any(side.startswith("fe-") for side in case.sides) and case.sides[0] in ("dem", "edem"):
            assert (case.scene, case.sides) == (twin.scene, twin.sides)
            assert case.overrides == {**twin.overrides, **(THESIS_BED if case.name == THRESHOLD_CASE else {})}
            judged = banded - ({"contact_area_rel_error"} if case.name == THRESHOLD_CASE else set())
            assert {m for m, b in case.bases().items() if b.kind == "model-band"} == judged
        else:
            assert twin == case
    # the threshold law's one row: its area set by h_max (by construction), judged against the same band
    threshold = quick.case(THRESHOLD_CASE)
    assert threshold.overrides["cartilage.law"] == "threshold" and threshold.overrides["cartilage.coupling"] == THESIS_BED["cartilage.coupling"]
    assert threshold.bases()["contact_area_rel_error"].kind == "by-construction" and "h_max" in threshold.bases()["contact_area_rel_error"].reason
    assert threshold.tolerance["contact_area_rel_error"] == MODEL_BAND_REL
    # one static row of the threshold law against the FE (the viscoelastic case is the ideal ankle's twin over time)
    assert [c.name for c in quick.cases if c.overrides.get("cartilage.law") == "threshold" and c.sides[0] == "dem" and c.sides[-1].startswith("fe-")] == [THRESHOLD_CASE]
    assert quick.case("ideal-standing-edem-vs-dem").sides == ("edem", "dem")
    assert quick.cases[0].name in answer  # the ankle answer first
    assert [a.kind for a in quick.analyses] == ["trust"]


def test_quick_answers_on_both_cartilage_ankles_with_both_beds_sharing_one_fe_run_per_ankle_and_nu():
    """The beds differ only in the keys the FE never reads, so each (ankle, nu) runs one FE (the
    runner's side store), against the two-layer FE at every load; each bed named in the overrides."""
    quick = get_campaign("quick")
    for ankle, (scene, _what) in ANKLES.items():
        for nu in ANSWER_NUS:
            cases = [quick.case(ankle_case_name(ankle, bed, nu)) for bed in ANSWER_BEDS]
            assert all(case.scene == scene and case.sides == ("dem", "fe-two-layer") for case in cases)
            fe_inputs = [side_inputs(case.sides[1], case.overrides, case.options) for case in cases]
            assert all(inputs == fe_inputs[0] for inputs in fe_inputs)
            assert all(is_shared_side(case.sides[1]) for case in cases)
            assert [case.overrides["cartilage.coupling"] for case in cases] == [ANKLE_BEDS[bed][0]["cartilage.coupling"] for bed in ANSWER_BEDS]
            assert all(case.overrides["load.force_n"] == [[0.0, 0.0, f] for f in LOADS_N] for case in cases)
            assert all(case.params["poissons_ratio"] == case.overrides["cartilage.poissons_ratio"] == nu for case in cases)
    # the labels the report and the answer use are the beds' own (edem.beds), not the keys' values
    labels = {bed_label(c) for c in answer_cases()}
    assert labels == {"coupled layer", "independent springs"}


def test_built_in_ankle_scenes_of_one_time_point_default_to_the_bed_the_trust_summary_calls_default():
    """The main job's "default bed" is what `edem run ideal-standing` uses; the thesis's springs stay one --set away."""
    default = ANKLE_BEDS[ANSWER_BEDS[0]][0]
    for scene in ("ideal-standing", "ideal-toe-off", "subject-standing", "subject-toe-off"):
        cartilage = load_scene(scene).cartilage
        assert (cartilage.coupling, cartilage.bed_keys.thin_layer_symbol, cartilage.bed_keys.thin_layer_stack) == (
            default["cartilage.coupling"], default["cartilage.thin_layer_symbol"], default["cartilage.thin_layer_stack"])
        assert load_scene(scene, THESIS_BED).cartilage.coupling == "none"


def test_thesis_comparisons_name_the_thesis_bed():
    """Cases set beside the thesis's figures run its bed whatever the scenes' default."""
    thesis_cases = [get_campaign("stance").case(f"{scene}-edem-vs-dem") for scene in ("ideal-stance", "subject-stance")]
    thesis_cases += list(get_campaign("sensitivity").cases)
    assert all(case.overrides["cartilage.coupling"] == THESIS_BED["cartilage.coupling"] for case in thesis_cases)


def test_verify_list_prints_one_line_per_campaign_with_case_count_and_time(capsys):
    assert main(["verify", "--list"]) == 0
    out = capsys.readouterr().out
    assert out == describe_campaigns()
    known = campaigns()
    lines = out.splitlines()
    assert len(lines) == len(known) + 1  # one per campaign and the note on how times were measured
    for campaign, line in zip(known.values(), lines):
        assert line.split()[:3] == [campaign.name, str(len(campaign.cases)), "cases"]
        assert campaign.expected_time_s is not None and "~" in line  # every campaign states its expected time


def test_verify_list_of_one_campaign_prints_its_cases(capsys):
    assert main(["verify", "--list", "stability"]) == 0
    out = capsys.readouterr().out
    campaign = get_campaign("stability")
    assert out.splitlines()[0].startswith(f"stability ({len(campaign.cases)} cases, ")
    for case in campaign.cases:
        assert sum(1 for line in out.splitlines() if line.split()[:1] == [case.name]) == 1


def test_unknown_campaign_is_bad_input(capsys):
    with pytest.raises(InputError):
        get_campaign("no-such-campaign")
    assert main(["verify", "no-such-campaign"]) == 2
    assert "unknown campaign" in capsys.readouterr().err


def test_stability_campaign_every_case_ends_in_its_declared_outcome(tmp_path):
    """Converges (residual below 1e-8 of the load, pressure = F/A where the plates allow it) or is
    refused with the declared message, and no output holds a NaN."""
    campaign = get_campaign("stability")
    summary = run_campaign(campaign, tmp_path / "stability", jobs=2, report=False)
    failures = [(r["name"], r["outcome"], r["verdicts"]) for r in summary["cases"] if r["status"] not in ("verified", "refused as declared")]
    assert not failures
    declared = {o: sum(1 for c in campaign.cases if c.expect.outcome == o) for o in ("converges", "refused")}
    assert summary["outcomes"] == declared
    for row in summary["cases"]:
        assert row["metrics"]["outcome_mismatch"] == 0.0
        assert row["metrics"]["non_finite_outputs"] == 0.0


def test_edem_analytic_campaign_passes_its_closed_forms(tmp_path):
    summary = run_campaign(get_campaign("edem-analytic"), tmp_path / "analytic", jobs=2, report=False)
    assert summary["exit_status"] == 0, [(r["name"], r["verdicts"]) for r in summary["cases"] if r["status"] != "verified"]
    assert summary["counts"]["verified"] == len(summary["cases"])  # closed forms: every case makes a claim
    rows = {r["name"]: r for r in summary["cases"]}
    # convergence: the log-law error halves as the step count doubles (first order)
    errors = [rows[f"log-law-n{n}"]["metrics"]["displacement_rel_error"] for n in (4, 8, 16, 32, 64, 128)]
    ratios = [a / b for a, b in zip(errors, errors[1:])]
    assert all(1.8 < r < 2.2 for r in ratios)
    # the hemisphere mean thickness approaches 0.5 as the target is refined
    gaps = [abs(rows[f"hemisphere-L{k}"]["metrics"]["thickness_mean_mm"] - 0.5) for k in range(1, 7)]
    assert gaps[-1] < 1e-3 < gaps[0]
