"""The main job's trust summary (verification.analyses.trust_analysis) on rows built here: signed
errors per ankle, bed and load (each case's time points, read from its metrics.json as the runner
writes it), the contact area's growth with the load against the goal, the goal said where missed,
and the threshold law's one row with its area said to be set by h_max."""

from __future__ import annotations

import json

from verification.analyses import trust_analysis
from verification.campaign_model import Analysis
from verification.campaigns.quick import campaign

LOADS = (333.0, 1000.0, 2000.0)


def _row(tmp_path, name: str, disp: list[tuple[float, float]], peak: list[tuple[float, float]], area: list[tuple[float, float]]) -> dict:
    """A case row against the FE at LOADS: (DEM, FE) of displacement (along z), regularised peak
    and contact area at each load, in its metrics.json's per-time comparison."""
    per_time = [{"load_n": f, "displacement_a_mm": [0.0, 0.0, d[0]], "displacement_b_mm": [0.0, 0.0, d[1]],
                 "regularised_peak_pressure_a_mpa": p[0], "regularised_peak_pressure_b_mpa": p[1],
                 "contact_area_a_mm2": a[0], "contact_area_b_mm2": a[1], "pressure_l2_rel_error": 0.1,
                 "displacement_rel_error": (d[0] - d[1]) / d[1]}  # along z only: the vector difference is the norms'
                for f, d, p, a in zip(LOADS, disp, peak, area, strict=True)]
    (tmp_path / "cases" / name).mkdir(parents=True)
    (tmp_path / "cases" / name / "metrics.json").write_text(json.dumps({"comparison": {"per_time": per_time}}))
    return {"status": "verified", "params": {"poissons_ratio": 0.42}, "metrics": {"displacement_rel_error": 0.0},
            "out_dir": str(tmp_path), "case_dir": f"cases/{name}"}


def _threshold_row() -> dict:
    """The threshold law's row: one load, values from its metrics (no per-time comparison)."""
    metrics = {"a_at_b_displacement_norm_mm": 0.3, "b_displacement_norm_mm": 0.4, "a_at_b_regularised_peak_pressure_mpa": 1.0,
               "b_regularised_peak_pressure_mpa": 1.1, "a_at_b_mean_contact_area_mm2": 463.4, "b_mean_contact_area_mm2": 420.0}
    return {"status": "verified", "params": {"poissons_ratio": 0.42, "load_n": 333.0}, "metrics": metrics}


def _analysis(rows: dict) -> dict:
    quick = next(a for a in campaign().analyses if a.kind == "trust")
    settings = dict(quick.settings)
    settings.update({"ankles": {"ideal ankle": {"coupled layer": ["c"], "independent springs": ["s"]}}, "threshold": "t",
                     "layer_cases": [], "low_load": "none", "layer_base": "none"})
    return trust_analysis(Analysis("trust", "t", "trust", tuple(rows), settings), rows)


def test_signed_errors_at_each_load_the_area_growth_and_the_goal(tmp_path):
    rows = {
        # the coupled layer: within 10 % everywhere but its area at 333 N (+20 %)
        "c": _row(tmp_path, "c", [(0.19, 0.2), (0.42, 0.4), (0.6, 0.6)], [(1.0, 1.0), (2.0, 2.1), (3.0, 3.0)], [(360.0, 300.0), (470.0, 450.0), (610.0, 600.0)]),
        # the springs: displacement -50 % at every load, an area that does not grow 1.25x
        "s": _row(tmp_path, "s", [(0.1, 0.2), (0.2, 0.4), (0.3, 0.6)], [(1.0, 1.0), (2.0, 2.0), (3.0, 3.0)], [(500.0, 300.0), (520.0, 450.0), (540.0, 600.0)]),
        "t": _threshold_row(),
    }
    result = _analysis(rows)
    sentences = result["values"]["sentences"]
    assert sentences[0].startswith("The default bed, the coupled layer, on the ideal ankle") and "333 / 1000 / 2000 N" in sentences[0]
    assert "the talus moves 0.19 / 0.42 / 0.6 mm against 0.2 / 0.4 / 0.6 mm (-5 %, +5 %, 0 %)" in sentences[0]  # signed; nothing is "-0 %"
    springs = next(s for s in sentences if s.startswith("Ideal ankle, independent springs"))
    assert "displacement -50 %, -50 %, -50 %" in springs  # signed, at each load, not |e|
    growth = next(s for s in sentences if s.startswith("The contact area grows"))
    assert "coupled layer 360 -> 610 mm² (1.69x; the FE 300 -> 600 mm², 2.00x)" in growth
    assert "independent springs 500 -> 540 mm² (1.08x; the FE 300 -> 600 mm², 2.00x), short of 1.25x" in growth
    goal = next(s for s in sentences if s.startswith("Goal"))
    # only the default bed's misses, each with its load and why (no FE study here: unknown, so no verdict)
    assert "): not judged; outside it: contact area on the ideal ankle at 333 N (+20 %: FE error unknown); the FE's own error unknown" in goal
    assert "outside it: displacement" not in goal and "the ideal ankle: displacement unknown, regularised peak pressure unknown, contact area unknown" in goal
    threshold = next(s for s in sentences if s.startswith("The thesis's threshold law"))
    assert "463.4 against 420 mm² (+10 %)" in threshold and "set by h_max" in threshold
    # the table: one row per case and load, the threshold's one row
    assert [r["cells"][:2] for r in result["rows"]] == [["c", "333"], ["c", "1000"], ["c", "2000"], ["s", "333"], ["s", "1000"], ["s", "2000"], ["t", "333"]]


def _with_fe_error(tmp_path, monkeypatch, row: dict, errors: dict[str, float]) -> dict:
    """``row`` as the quick answer's first case (its FE run), with ``errors`` stored as that run's own error."""
    from verification import fe_convergence
    from verification.campaigns.quick import answer_cases

    case = answer_cases()[0]
    file = tmp_path / "fe_convergence.json"
    key = fe_convergence.fe_key(case.scene, case.sides[-1], case.overrides, case.options)
    file.write_text(json.dumps({"entries": {key: {"case": "x", "errors": errors}}}))
    monkeypatch.setattr(fe_convergence, "REFERENCE_FILE", file)
    return {**row, "scene": case.scene, "sides": list(case.sides), "overrides": case.overrides, "options": case.options}


def test_goal_met_only_where_the_fes_own_error_is_known_and_below_it(tmp_path, monkeypatch):
    """Every card metric of the default bed within 10 % at every load: no verdict against an FE
    whose own error is unknown or not below the goal (that metric not judged), met against one
    whose error is known and below it; a metric outside the goal against such an FE is missed."""
    within = _row(tmp_path, "c", [(0.2, 0.2)] * 3, [(1.05, 1.0)] * 3, [(310.0, 300.0), (460.0, 450.0), (590.0, 600.0)])
    springs = _row(tmp_path, "s", [(0.1, 0.2)] * 3, [(0.7, 1.0)] * 3, [(300.0, 300.0)] * 3)  # the springs miss it: not the default bed's goal

    def goal(row) -> str:
        return next(s for s in _analysis({"c": row, "s": springs})["values"]["sentences"] if s.startswith("Goal"))

    assert "): not judged; the FE's own error unknown or not below the goal for displacement" in goal(within)  # no study
    known = {"displacement_rel_error": 0.004, "regularised_peak_pressure_rel_error": 0.021, "contact_area_rel_error": 0.013}
    met = goal(_with_fe_error(tmp_path, monkeypatch, within, known))
    assert "): met on every ankle compared." in met and "the ideal ankle: displacement 0.40 %, regularised peak pressure 2.10 %, contact area 1.30 %" in met
    coarse = goal(_with_fe_error(tmp_path, monkeypatch, within, {**known, "contact_area_rel_error": 0.10}))  # as large as the goal: judges nothing
    assert "): not judged; the FE's own error unknown or not below the goal for contact area on the ideal ankle." in coarse
    outside = _row(tmp_path, "c2", [(0.2, 0.2)] * 3, [(1.05, 1.0)] * 3, [(310.0, 300.0), (460.0, 450.0), (690.0, 600.0)])
    missed = goal(_with_fe_error(tmp_path, monkeypatch, outside, known))
    assert "): missed; outside it: contact area on the ideal ankle at 2000 N (+15 %: beyond the FE's own error 1.3 %)" in missed


def test_without_the_default_beds_comparison_the_answer_says_it_was_not_answered(tmp_path):
    rows = {"c": {"status": "unavailable", "sides": [{"status": "ok"}, {"status": "unavailable", "message": "dolfinx is not installed"}], "metrics": {}}}
    result = _analysis(rows)
    assert result["status"] == "unavailable" and "dolfinx is not installed" in result["values"]["sentences"][0]


def test_a_goal_miss_names_its_cause_by_construction_within_or_beyond_the_fes_own_error():
    """The area set by construction is said so; a miss no larger than the FE's own estimated error
    is put on the FE; one above it is a model error (bed or law); an FE run outside the study is 'unknown'."""
    from verification.analyses import _why_missed
    from verification.campaigns.quick import answer_cases
    from verification.fe_convergence import fe_key

    case = answer_cases()[0]
    row = {"scene": case.scene, "sides": list(case.sides), "overrides": case.overrides, "options": case.options,
           "verdicts": {"contact_area_rel_error": {"kind": "by-construction"}}}
    reference = {"entries": {fe_key(case.scene, case.sides[-1], case.overrides, case.options): {"errors": {"displacement_rel_error": 0.15,
                                                                                                          "regularised_peak_pressure_rel_error": 0.01}}}}
    assert _why_missed(row, "contact_area_rel_error", 0.2, reference) == ": by construction"
    assert _why_missed(row, "displacement_rel_error", -0.12, reference) == ": within the FE's own error 15.0 %"
    assert _why_missed(row, "regularised_peak_pressure_rel_error", -0.12, reference) == ": beyond the FE's own error 1.0 %"
    assert _why_missed(row, "regularised_peak_pressure_rel_error", -0.12, {"entries": {}}) == ": FE error unknown"
