"""Case verdicts mean what docs/campaigns.md says: a model band exceeded flags, anything else
exceeded fails, sanity bounds alone verify nothing, a declared refusal is its own verdict."""

from __future__ import annotations

import pytest

from verification.verdicts import (
    CLOSED_FORM,
    MODEL_BAND,
    SANITY,
    Basis,
    bases_for,
    case_verdict,
    count_verdicts,
    headline,
    tolerance_verdicts,
)

EXACT = Basis(CLOSED_FORM, "round-off")
BAND = Basis(MODEL_BAND, "declared band")
BROKEN = Basis(SANITY, "catches broken runs only")


def _verdict(metrics, tolerance, bases, statuses=("ok", "ok"), expected=None, refused=False):
    verdicts = tolerance_verdicts(metrics, tolerance, bases, not_applicable=refused)
    return case_verdict(list(statuses), verdicts, expected, refused)


def test_met_closed_form_tolerance_is_verified_and_a_missed_one_fails():
    assert _verdict({"e": 1e-12}, {"e": 1e-9}, {"e": EXACT}) == "verified"
    assert _verdict({"e": 2e-9}, {"e": 1e-9}, {"e": EXACT}) == "failed"


def test_model_band_exceeded_flags_instead_of_failing():
    assert _verdict({"e": 0.3, "x": 0.0}, {"e": 0.25, "x": 1e-9}, {"e": BAND, "x": EXACT}) == "flagged"
    assert _verdict({"e": 0.2}, {"e": 0.25}, {"e": BAND}) == "verified"


def test_a_failure_outranks_a_flag():
    assert _verdict({"e": 0.3, "x": 1.0}, {"e": 0.25, "x": 1e-9}, {"e": BAND, "x": EXACT}) == "failed"


def test_sanity_bounds_alone_make_no_verdict():
    assert _verdict({"e": 0.5}, {"e": 10.0}, {"e": BROKEN}) == "ran"
    assert _verdict({}, {}, {}) == "ran"
    assert _verdict({"e": 11.0}, {"e": 10.0}, {"e": BROKEN}) == "failed"


def test_refused_as_declared_is_its_own_verdict():
    bases = bases_for({"outcome_mismatch": 0.0, "force_residual_rel": 1e-8})
    assert _verdict({"outcome_mismatch": 0.0}, {"outcome_mismatch": 0.0, "force_residual_rel": 1e-8}, bases,
                    statuses=("refused",), expected="refused", refused=True) == "refused as declared"
    # declared to converge, refused: the declared outcome is missed
    assert _verdict({"outcome_mismatch": 1.0}, {"outcome_mismatch": 0.0}, bases_for({"outcome_mismatch": 0.0}),
                    statuses=("refused",), expected="converges") == "failed"


def test_unavailable_and_crashed_sides_come_first():
    assert _verdict({}, {"e": 1e-9}, {"e": EXACT}, statuses=("ok", "unavailable")) == "unavailable"
    assert _verdict({}, {"e": 1e-9}, {"e": EXACT}, statuses=("error", "ok")) == "error"


def test_every_tolerance_needs_a_reason():
    with pytest.raises(KeyError, match="peak_pressure_rel_error"):
        bases_for({"peak_pressure_rel_error": 0.1})
    with pytest.raises(ValueError):
        Basis(CLOSED_FORM, " ")
    with pytest.raises(ValueError):
        Basis("tuned", "why not")


def test_headline_counts_each_verdict():
    counts = count_verdicts(["verified", "flagged", "verified", "ran"])
    assert counts["verified"] == 2 and counts["flagged"] == 1 and counts["ran"] == 1 and counts["failed"] == 0
    assert headline(counts) == "2 verified, 1 flagged, 1 ran"


# ---------------------------------------------------------------------------------------------
# The design card's three metrics, signed errors, the FE's own error, metrics set by construction


def _quick_case(name):
    from verification.campaigns import get_campaign

    return get_campaign("quick").case(name)


def test_a_quick_ankle_case_with_displacement_minus_43_percent_is_not_verified():
    """An ankle case of the thesis's law was "verified" at displacement -43 % (checked against a 1000 %
    sanity bound only): displacement, the regularised peak and the pressure field are judged against
    the band, on the answer's cartilage ankles as on the threshold law's row."""
    from verification.campaigns.quick import THRESHOLD_CASE, answer_cases

    for case in (answer_cases()[0], _quick_case(THRESHOLD_CASE)):
        inside = {"regularised_peak_pressure_rel_error": -0.05, "pressure_l2_rel_error": 0.1, "contact_area_rel_error": 0.02,
                  "peak_pressure_rel_error": -0.3, "mean_pressure_rel_error": 0.0, "force_residual_rel": 0.0, "non_finite_outputs": 0.0}
        verdicts = tolerance_verdicts({**inside, "displacement_rel_error": -0.43}, case.tolerance, case.bases())
        assert verdicts["displacement_rel_error"]["verdict"] == "outside band"
        assert case_verdict(["ok", "ok"], verdicts, None, False) == "flagged"
        verdicts = tolerance_verdicts({**inside, "displacement_rel_error": -0.05}, case.tolerance, case.bases())
        assert case_verdict(["ok", "ok"], verdicts, None, False) == "verified"


@pytest.mark.parametrize("metric", ["regularised_peak_pressure_rel_error", "pressure_l2_rel_error", "displacement_rel_error"])
def test_each_card_metric_outside_the_band_stops_verified(metric):
    case = _quick_case("layer-F333-nu0.42-t2")
    values = {m: 0.0 for m in case.tolerance}
    values[metric] = -0.3 if metric != "pressure_l2_rel_error" else 0.3  # beyond the +-25 % band
    assert case_verdict(["ok", "ok"], tolerance_verdicts(values, case.tolerance, case.bases()), None, False) == "flagged"


def test_a_band_bounds_the_magnitude_of_a_signed_error():
    assert _verdict({"e": -0.3}, {"e": 0.25}, {"e": BAND}) == "flagged"
    assert _verdict({"e": -0.2}, {"e": 0.25}, {"e": BAND}) == "verified"
    assert _verdict({"e": -2e-9}, {"e": 1e-9}, {"e": EXACT}) == "failed"


def test_a_met_sanity_bound_is_reported_not_judged():
    verdicts = tolerance_verdicts({"e": 0.43}, {"e": 10.0}, {"e": BROKEN})
    assert verdicts["e"]["verdict"] == "reported, not judged"
    assert case_verdict(["ok", "ok"], verdicts, None, False) == "ran"


def test_a_band_not_larger_than_the_fe_error_judges_nothing():
    """The FE reference's estimated error (fe_errors, metric -> relative error) of 25 % or more
    leaves a 25 % band unable to judge: its own verdict, whatever the value; a smaller error
    leaves the band judging."""
    tolerance, bases = {"e": 0.25, "x": 1e-9}, {"e": BAND, "x": EXACT}
    for value in (0.01, -0.6):
        verdicts = tolerance_verdicts({"e": value, "x": 0.0}, tolerance, bases, fe_errors={"e": 0.25})
        assert verdicts["e"]["verdict"] == "FE not converged enough to judge" and verdicts["e"]["fe_error"] == 0.25
        assert case_verdict(["ok", "ok"], verdicts, None, False) == "FE not converged enough to judge"
    verdicts = tolerance_verdicts({"e": -0.6, "x": 0.0}, tolerance, bases, fe_errors={"e": 0.05})
    assert verdicts["e"]["verdict"] == "outside band" and case_verdict(["ok", "ok"], verdicts, None, False) == "flagged"
    assert tolerance_verdicts({"e": 0.1}, {"e": 0.25}, {"e": BAND}, fe_errors=None)["e"]["verdict"] == "met"


def test_the_runner_passes_a_cases_fe_errors_to_its_verdicts():
    import dataclasses

    from verification.runner import judge

    case = dataclasses.replace(_quick_case("layer-F333-nu0.42-t2"), fe_errors={"contact_area_rel_error": 0.3})
    record = {"sides": [{"status": "ok"}, {"status": "ok"}], "metrics": {m: 0.0 for m in case.tolerance}}
    status, verdicts = judge(case, record)
    assert status == "FE not converged enough to judge" and verdicts["contact_area_rel_error"]["fe_error"] == 0.3
    # with the FE's error known and small for every judged metric, a case inside its band is verified
    small = {m: 0.01 for m in case.tolerance}
    assert judge(case, record, fe_errors=small)[0] == "verified"
    # with none known, an FE reference judges nothing (FE error unknown)
    assert judge(case, record, fe_errors={})[0] == "FE not converged enough to judge"


def test_an_area_set_by_construction_is_still_judged_against_the_band():
    """463 mm^2 at every load and nu by construction, and still a card metric: inside the band it is
    met, outside it the case is flagged (verified needs all three inside), and its reason says the
    law sets it."""
    case = _quick_case("slab-F333-nu0.42")
    band = case.tolerance["contact_area_rel_error"]
    for area_error, verdict, case_status in ((0.5 * band, "met", "verified"), (-2.0 * band, "outside band", "flagged")):
        values = {m: 0.0 for m in case.tolerance}
        values["contact_area_rel_error"] = area_error
        verdicts = tolerance_verdicts(values, case.tolerance, case.bases())
        assert verdicts["contact_area_rel_error"]["verdict"] == verdict
        assert verdicts["contact_area_rel_error"]["kind"] == "by-construction" and "by construction" in verdicts["contact_area_rel_error"]["reason"]
        assert case_verdict(["ok", "ok"], verdicts, None, False) == case_status
