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
