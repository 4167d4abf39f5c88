"""The FE reference's own error (issue 24, item 1): Richardson's observed order and extrapolation
against closed-form sequences, the area percentile of the pressure, and the lookup by which a
campaign's FE reference finds its error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from verification.campaign_model import Case
from verification.fe_convergence import fe_key, fe_relative_error, pressure_percentile_by_area, richardson
from verification.verdicts import FE_ERROR_UNKNOWN


@pytest.mark.parametrize("order", [1.0, 2.0, 3.0])
@pytest.mark.parametrize("sizes", [(2.0, 1.0, 0.5), (2.0, 1.41, 0.7), (1.9, 1.0, 0.61)])
def test_richardson_recovers_the_order_and_limit_of_f0_plus_c_h_to_the_p(order, sizes):
    """f(h) = f0 + C h^p exactly: the observed order is p, the extrapolation f0 and each mesh's
    error C h^p / f0, also for unequal refinement ratios (the fixed-point order). Tolerance
    1e-9 relative: the fixed point stops at 1e-12 and the rest is round-off of a few logs."""
    f0, c = 5.0, -0.3
    values = [f0 + c * h**order for h in sizes]
    est = richardson(sizes, values)
    assert est.asymptotic
    assert est.order == pytest.approx(order, rel=1e-9)
    assert est.extrapolated == pytest.approx(f0, rel=1e-9)
    np.testing.assert_allclose(est.errors, [abs(c) * h**order / f0 for h in sizes], rtol=1e-8)


def test_an_oscillating_sequence_is_not_asymptotic_and_its_error_is_the_spread():
    """Differences of both signs: no order, no extrapolation; each mesh's error is its largest
    difference to the other meshes over the finest value (what refining was seen to change)."""
    est = richardson((2.0, 1.0, 0.5), (1.0, 1.1, 1.05))
    assert not est.asymptotic and est.extrapolated is None and math.isnan(est.order)
    assert est.errors == pytest.approx((0.1 / 1.05, 0.1 / 1.05, 0.05 / 1.05))


def test_an_order_outside_the_believed_range_is_not_extrapolated():
    """f = 1 + h^6: p = 6 is far above P2's orders, so the meshes are not taken as asymptotic."""
    sizes = (2.0, 1.0, 0.5)
    est = richardson(sizes, [1.0 + h**6 for h in sizes])
    assert est.order == pytest.approx(6.0) and not est.asymptotic and est.extrapolated is None


def test_richardson_refuses_meshes_that_are_not_refined():
    with pytest.raises(ValueError):
        richardson((1.0, 1.0, 0.5), (1.0, 2.0, 3.0))
    with pytest.raises(ValueError):
        richardson((1.0, 0.5), (1.0, 2.0))


def test_each_mesh_is_estimated_from_the_finest_three_meshes_that_contain_it():
    """Three meshes: one estimate for all; more: every mesh but the coarsest from the finest three."""
    from verification.fe_convergence import finest_windows

    assert finest_windows(3) == (0, 0, 0)
    assert finest_windows(4) == (0, 1, 1, 1)
    assert finest_windows(5) == (0, 1, 2, 2, 2)
    with pytest.raises(ValueError):
        finest_windows(2)


@pytest.mark.parametrize("order", [1.0, 2.0, 3.0])
def test_meshes_refined_in_plane_only_read_their_order_from_the_triangles(order):
    """Halving the triangles of a layer of fixed elements through it multiplies the DOFs by 4:
    with one ``layers_through_thickness`` the size is N^(-1/2) and f0 + C h^p reads order p; the
    same DOFs taken as a refinement in 3D (N^(-1/3)) would read 1.5 p. Tolerance 1e-9 relative:
    the fixed-point order stops at 1e-12, the rest is round-off."""
    from verification.fe_convergence import level_estimates

    dofs = (1e5, 4e5, 16e5)
    h = [n ** -0.5 for n in dofs]
    values = [2.0 + 0.1 * (x / h[0]) ** order for x in h]  # a 5 % correction on the coarsest: no cancellation
    (flat, *_), (general, *_) = level_estimates(dofs, values, [2, 2, 2]), level_estimates(dofs, values, [1, 2, 2])
    assert flat.order == pytest.approx(order, rel=1e-9) and flat.extrapolated == pytest.approx(2.0, rel=1e-9)
    assert general.order == pytest.approx(1.5 * order, rel=1e-9)


def test_a_finer_mesh_estimates_the_campaigns_level_from_the_finest_three_not_the_coarse_jump():
    """Four meshes: one element per layer at the coarse triangles, then two elements per layer with
    the triangles halved twice (f0 + C h^2 exactly on those three, h = N^(-1/2)), the coarsest off
    that line so that the first three oscillate. The first three alone give the third mesh the
    spread (its jump from the second); the four give it its Richardson error C h^2 / f0 from the
    finest three, and the coarsest keeps the first three's spread. Tolerance 1e-9 relative: a
    closed-form sequence, round-off only."""
    from verification.fe_convergence import level_estimates

    f0, c = 170.0, -2e7
    dofs = (6e4, 1e5, 4e5, 16e5)
    layers = (1, 2, 2, 2)
    fine = [f0 + c * n ** -1.0 for n in dofs[1:]]  # C h^2 with h = N^(-1/2)
    values = [fine[0] + 2.0, *fine]  # the coarsest above the second, the second far below the third: the first three oscillate
    three = level_estimates(dofs[:3], values[:3], layers[:3])
    assert not three[2].asymptotic and three[2].errors[2] == pytest.approx(abs(values[2] - values[1]) / values[2], rel=1e-9)
    four = level_estimates(dofs, values, layers)
    assert four[2] is four[3] is four[1] and four[2].asymptotic and four[2].order == pytest.approx(2.0, rel=1e-9)
    assert four[2].errors[1] == pytest.approx(abs(c) / dofs[2] / f0, rel=1e-9)  # mesh 2 is the middle of the finest three
    assert four[0].errors == pytest.approx(three[0].errors, rel=1e-12)  # the coarsest: the first three's estimate


def test_the_study_stores_each_level_of_a_four_mesh_point_with_the_error_of_its_finest_three():
    """The fe-convergence analysis of a point on four meshes: the third mesh's stored error is
    the finest three's Richardson error (closed form), its record says which three each mesh was
    estimated from, and the table shows four values. Tolerance 1e-9 relative: round-off."""
    from verification.analyses import fe_convergence_analysis
    from verification.campaign_model import Analysis
    from verification.fe_convergence import FE_VALUE_METRICS
    from verification.status import OK

    f0, c = 3.0, -2e4
    dofs = (6e4, 1e5, 4e5, 16e5)
    layers = (1, 2, 2, 2)
    values = [f0 + 0.2, *(f0 + c / n for n in dofs[1:])]
    names = [f"p-h{k}" for k in range(4)]
    options = [{"mesh_size_mm": s, "degree": 2, "layers_through_thickness": n} for s, n in zip((1.0, 1.0, 0.7, 0.35), layers)]

    def row(n: float, value: float, opts: dict) -> dict:
        metrics = {m: value for m in FE_VALUE_METRICS}
        metrics.update(fe_n_dofs=n, fe_wall_time_s=1.0, fe_peak_memory_mb=1.0)
        return {"sides": [{"side": "fe-two-layer", "status": OK}], "metrics": metrics, "options": opts}

    rows = {name: row(n, v, o) for name, n, v, o in zip(names, dofs, values, options)}
    point = {"point": "p", "levels": names, "extra": None, "scene": "cylinder-two-layers", "side": "fe-two-layer", "overrides": {}}
    result = fe_convergence_analysis(Analysis("c", "c", "fe-convergence", tuple(rows), {"points": [point], "findings": []}), rows)
    entry = result["values"]["entries"][fe_key("cylinder-two-layers", "fe-two-layer", {}, options[2])]
    assert entry["case"] == "p-h2"
    assert entry["errors"]["displacement_rel_error"] == pytest.approx(abs(c) / dofs[2] / f0, rel=1e-9)
    record = result["values"]["points"][0]["quantities"]["displacement"]
    assert record["estimated_from"] == [0, 1, 1, 1] and record["asymptotic"] and record["order"] == pytest.approx(2.0, rel=1e-9)
    cells = [r["cells"] for r in result["rows"] if r["cells"][1] == "displacement"][0]
    assert len(cells[2].split(", ")) == 4 and len(cells[5].split(", ")) == 4
    assert len(result["values"]["entries"]) == 4


def _grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, n + 1))
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    k = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    triangles = np.concatenate([np.column_stack([k, k + 1, k + n + 2]), np.column_stack([k, k + n + 2, k + n + 1])])
    return vertices, triangles


def test_one_node_cannot_set_the_area_percentile_but_two_percent_of_the_area_can():
    """A uniform 1 MPa on a unit square with one interior node at 100 MPa (lumped area 1/400 of
    the square, under 2 %): the 98th percentile stays 1 while the nodal peak is 100. Raising the
    pressure on 3 % of the area (more than the 2 % above the 98th) moves it to that pressure."""
    vertices, triangles = _grid(20)
    p = np.ones(len(vertices))
    p[10 * 21 + 10] = 100.0
    assert p.max() == 100.0
    assert pressure_percentile_by_area(p, vertices, triangles) == 1.0
    q = np.where(vertices[:, 0] > 0.96, 7.0, 1.0)  # the strip x > 0.96: 2.5 % of the area by lumping (one column of nodes)
    assert pressure_percentile_by_area(q, vertices, triangles) == 7.0
    assert pressure_percentile_by_area(np.zeros(len(vertices)), vertices, triangles) == 0.0


def _case(options: dict, overrides: dict | None = None, sides=("dem", "fe-slab")) -> Case:
    return Case("c", "a case", "ideal-standing", sides, (), overrides=overrides or {"cartilage.poissons_ratio": 0.42}, options=options)


def test_a_case_finds_the_error_of_its_own_fe_run_and_only_that():
    """Keyed by what the FE reads: the same FE run (a bed override the FE ignores) finds the
    entry; another mesh size, degree, Poisson's ratio or a case without an FE side does not."""
    run = _case({"mesh_size_mm": 1.0, "degree": 2})
    errors = {"peak_pressure_rel_error": 0.031, "contact_area_rel_error": 0.012, "displacement_rel_error": 0.004}
    reference = {"entries": {fe_key(run.scene, "fe-slab", run.overrides, run.options): {"case": "x", "errors": errors}}}
    assert fe_relative_error(run, reference) == errors
    coupled = _case({"mesh_size_mm": 1, "degree": 2}, {"cartilage.poissons_ratio": 0.42, "cartilage.coupling": "thin-layer"})
    assert fe_relative_error(coupled, reference) == errors
    assert fe_relative_error(_case({"mesh_size_mm": 0.7, "degree": 2}), reference) is None
    assert fe_relative_error(_case({"mesh_size_mm": 1.0, "degree": 1}), reference) is None
    assert fe_relative_error(_case({"mesh_size_mm": 1.0, "degree": 2}, {"cartilage.poissons_ratio": 0.3}), reference) is None
    assert fe_relative_error(_case({}, sides=("edem", "dem")), reference) is None


def test_a_campaign_table_shows_the_fe_error_of_a_studied_run_and_says_unknown_otherwise(tmp_path, monkeypatch):
    """The table analysis's fe_error columns: the stored estimate for a case whose FE run is in
    the study, "unknown" for one whose run is not (another mesh size)."""
    import json

    from verification import fe_convergence
    from verification.analyses import table_analysis
    from verification.campaign_model import Analysis

    studied = {"mesh_size_mm": 1.0, "degree": 2}
    key = fe_key("ideal-standing", "fe-slab", {"cartilage.poissons_ratio": 0.42}, studied)
    file = tmp_path / "fe_convergence.json"
    file.write_text(json.dumps({"entries": {key: {"case": "x", "errors": {"peak_pressure_rel_error": 0.0312}}}}))
    monkeypatch.setattr(fe_convergence, "REFERENCE_FILE", file)

    def row(options):
        return {"scene": "ideal-standing", "sides": [{"side": "dem", "status": "ok"}, {"side": "fe-slab", "status": "ok"}],
                "overrides": {"cartilage.poissons_ratio": 0.42}, "options": options, "metrics": {"peak_pressure_rel_error": 0.1}, "status": "ran"}

    columns = [{"header": "peak err", "metric": "peak_pressure_rel_error"}, {"header": "FE err", "fe_error": "peak_pressure_rel_error"}]
    result = table_analysis(Analysis("t", "t", "table", ("a", "b"), {"columns": columns}), {"a": row(studied), "b": row({"mesh_size_mm": 0.7, "degree": 2})})
    assert result["columns"] == ["case", "peak err", "FE err", "note"]
    assert result["rows"][0]["cells"][2] == "3.12 %"
    assert result["rows"][1]["cells"][2] == "unknown"


def test_a_judged_case_takes_its_fe_error_from_the_study_and_a_band_within_it_judges_nothing(tmp_path, monkeypatch):
    """A quick trust case (judged against the 25 % model band) whose FE run is in the stored study:
    every judged metric carries the study's FE error, and a metric whose FE error is not below
    the band is 'FE not converged enough to judge' whatever its value; one whose run is not in
    the study is flagged outside the band but cannot meet it: inside, its metric is 'FE error
    unknown' and the case is not verified."""
    import json

    from verification import fe_convergence
    from verification.campaigns.quick import trust_cases
    from verification.runner import judge
    from verification.status import FE_NOT_CONVERGED, FLAGGED

    case = next(c for c in trust_cases() if c.name == "slab-F333-nu0.42")
    key = fe_key(case.scene, case.sides[-1], case.overrides, case.options)
    file = tmp_path / "fe_convergence.json"
    file.write_text(json.dumps({"entries": {key: {"case": "x", "errors": {"displacement_rel_error": 0.30, "regularised_peak_pressure_rel_error": 0.02}}}}))
    monkeypatch.setattr(fe_convergence, "REFERENCE_FILE", file)
    metrics = {m: 0.05 for m in case.tolerance}
    metrics.update(force_residual_rel=1e-12, non_finite_outputs=0.0)  # the invariants hold
    metrics["displacement_rel_error"] = -0.40  # outside the band, but the FE's own error (30 %) exceeds the band (25 %)
    record = {"sides": [{"status": "ok"}, {"status": "ok"}], "metrics": metrics}
    status, verdicts = judge(case, record)
    assert verdicts["displacement_rel_error"]["verdict"] == FE_NOT_CONVERGED and verdicts["displacement_rel_error"]["fe_error"] == 0.30
    assert verdicts["regularised_peak_pressure_rel_error"]["verdict"] == "met" and verdicts["regularised_peak_pressure_rel_error"]["fe_error"] == 0.02
    assert status == FE_NOT_CONVERGED
    other = next(c for c in trust_cases() if c.name == "layer-F333-nu0.42-t2")  # not in this study: judged on its value
    status, verdicts = judge(other, record)
    assert status == FLAGGED and "fe_error" not in verdicts["displacement_rel_error"]
    assert verdicts["regularised_peak_pressure_rel_error"]["verdict"] == FE_ERROR_UNKNOWN
    inside = {"sides": record["sides"], "metrics": {**metrics, "displacement_rel_error": -0.05}}
    assert judge(other, inside)[0] == FE_NOT_CONVERGED
    assert judge(case, inside)[0] == FE_NOT_CONVERGED  # still: the displacement's FE error (30 %) exceeds the band


def test_a_band_met_against_a_closed_form_needs_no_fe_error():
    """The 'FE error unknown' rule is about FE references only: the same model band met by a
    case without an FE side is met."""
    from verification.verdicts import MODEL_BAND, Basis, case_verdict, tolerance_verdicts

    bases = {"x_rel_error": Basis(MODEL_BAND, "a declared band")}
    assert tolerance_verdicts({"x_rel_error": 0.1}, {"x_rel_error": 0.25}, bases)["x_rel_error"]["verdict"] == "met"
    verdicts = tolerance_verdicts({"x_rel_error": 0.1}, {"x_rel_error": 0.25}, bases, fe_reference=True)
    assert verdicts["x_rel_error"]["verdict"] == FE_ERROR_UNKNOWN
    assert case_verdict(["ok", "ok"], verdicts, None, False) == "FE not converged enough to judge"


@pytest.mark.parametrize("order", [1.5, 2.0, 3.0])
def test_field_errors_of_fields_on_a_line_are_their_distances_from_the_limit(order):
    """p_h = p* + h^q e (one error shape): the differences from the finest mesh are
    (h^q - h3^q) |e| / |p3|, and the estimated L2 error of each mesh is h^q |e| / |p3| exactly
    (Richardson on the positions along the line; 1e-8: the fixed-point order, as above)."""
    from verification.fe_convergence import field_errors

    sizes, c = (2.0, 1.2, 0.7), 0.013  # c = |e| / |p3|
    s = [c * (h**order - sizes[2] ** order) for h in sizes]
    est = field_errors(sizes, (s[0], s[1]), s[0] - s[1])
    assert est.asymptotic and est.order == pytest.approx(order, rel=1e-9)
    np.testing.assert_allclose(est.errors, [c * h**order for h in sizes], rtol=1e-8)


def test_field_errors_off_a_line_are_the_largest_differences_seen():
    """Coarse fields not on one line through the finest (the coarse-to-middle difference is not
    the difference of their distances from the finest): no extrapolation; each mesh's error is
    its largest difference from the others."""
    from verification.fe_convergence import field_errors

    est = field_errors((2.0, 1.0, 0.7), (0.05, 0.03), 0.06)
    assert not est.asymptotic and est.extrapolated is None
    assert est.errors == pytest.approx((0.06, 0.06, 0.05))


def test_a_historys_unloading_branch_takes_the_fes_own_error_against_the_cycles_peak(monkeypatch):
    """A Kelvin-Voigt cycle (333 N held, then 33.3 N held) whose quantities are f0(t) + A h^2 on
    three meshes (h ~ N^(-1/3)) with f0 ten times smaller after the unloading: against each
    instant's own value the unloaded instants' error would be ten times the loaded ones'; taken
    against the cycle's peak, as the comparisons take theirs (verification.metrics.against_cycle_peak),
    each mesh's stored error is A h^2 / f0_peak at every instant. Tolerance 1e-9 relative: round-off."""
    import verification.analyses as analyses
    from verification.campaign_model import Analysis
    from verification.fe_convergence import FE_VALUE_METRICS
    from verification.status import OK

    dofs, a = (1e3, 8e3, 64e3), 2.0
    f0 = (10.0, 10.0, 1.0, 1.0)
    loads = (333.0, 333.0, 33.3, 33.3)
    h = [n ** (-1.0 / 3.0) for n in dofs]
    names = ["cycle-h2", "cycle-h1", "cycle-h0.7"]
    rows = {n: {"sides": [{"side": "fe-layer", "status": OK}], "options": {"mesh_size_mm": s, "degree": 2},
                "metrics": {"fe_n_dofs": d, "fe_wall_time_s": 1.0, "fe_peak_memory_mb": 1.0}} for n, s, d in zip(names, (2.0, 1.0, 0.7), dofs)}
    by_time = [[{**{m: f + a * hi * hi for m in FE_VALUE_METRICS}, "load_n": load, "time_s": float(k)} for hi in h]
               for k, (f, load) in enumerate(zip(f0, loads))]
    monkeypatch.setattr(analyses, "_values_by_time", lambda level_rows: by_time)
    point = {"point": "cycle", "levels": names, "extra": None, "scene": "cylinder-layer", "side": "fe-layer", "overrides": {}}
    result = analyses.fe_convergence_analysis(Analysis("c", "c", "fe-convergence", tuple(rows), {"points": [point], "findings": []}), rows)
    for name, hi in zip(names, h):
        entry = result["values"]["entries"][fe_key("cylinder-layer", "fe-layer", {}, rows[name]["options"])]
        assert entry["errors"]["displacement_rel_error"] == pytest.approx(a * hi * hi / max(f0), rel=1e-9)
    unloaded = result["values"]["points"][0]["quantities"]["displacement at t = 2 s (33.3 N)"]
    assert unloaded["relative_to"] == "cycle peak" and unloaded["errors"][2] == pytest.approx(a * h[2] ** 2 / f0[2], rel=1e-9)


def test_a_point_whose_meshes_are_not_distinct_is_reported_without_an_estimate_and_the_others_still_are():
    """A 1 mm layer gets one element through it at 2.0 and at 1.0 mm: the same mesh twice. That
    point says so (no three-level estimate); a properly refined point beside it is estimated."""
    from verification.analyses import fe_convergence_analysis
    from verification.campaign_model import Analysis
    from verification.fe_convergence import FE_VALUE_METRICS
    from verification.status import OK

    def row(dofs: float, value: float) -> dict:
        metrics = {m: value for m in FE_VALUE_METRICS}
        metrics.update(fe_n_dofs=dofs, fe_wall_time_s=1.0, fe_peak_memory_mb=1.0)
        return {"sides": [{"side": "fe-layer", "status": OK}], "metrics": metrics, "options": {"mesh_size_mm": 1.0, "degree": 2}}

    rows = {"same-h2": row(32e3, 1.0), "same-h1": row(32e3, 1.0), "same-h0.7": row(210e3, 1.1),
            "fine-h2": row(1e3, 1.0 + 0.1), "fine-h1": row(8e3, 1.0 + 0.1 / 4), "fine-h0.7": row(64e3, 1.0 + 0.1 / 16)}
    points = [{"point": p, "levels": [f"{p}-h2", f"{p}-h1", f"{p}-h0.7"], "extra": None, "scene": "cylinder-layer", "side": "fe-layer",
               "overrides": {}} for p in ("same", "fine")]
    result = fe_convergence_analysis(Analysis("c", "c", "fe-convergence", tuple(rows), {"points": points, "findings": []}), rows)
    same = [r["cells"] for r in result["rows"] if r["cells"][0] == "same"]
    assert len(same) == 1 and same[0][2].startswith("meshes not distinct")
    fine = [r["cells"] for r in result["rows"] if r["cells"][0] == "fine" and r["cells"][1] == "displacement"]
    assert fine and fine[0][3] == "2"  # h ~ N^(-1/3) halves, the error quarters: order 2


def test_an_override_that_repeats_the_scene_file_names_the_same_fe_run():
    """subject-standing's file sets nu 0.42: quick's override of 0.42 and the subject campaign's
    run without it are one FE run with one key, and one study entry serves both; 0.45 is another."""
    options = {"mesh_size_mm": 1.0, "degree": 2}
    same = fe_key("subject-standing", "fe-slab", {"ligaments": [], "cartilage.poissons_ratio": 0.42}, options)
    assert same == fe_key("subject-standing", "fe-slab", {"ligaments": []}, options)
    assert same != fe_key("subject-standing", "fe-slab", {"ligaments": [], "cartilage.poissons_ratio": 0.45}, options)


def test_every_fe_reference_of_the_judging_campaigns_is_a_mesh_level_of_the_study():
    """Issue 24, item 1: each FE reference of quick, subject, thin-layer, cylinder-plane and ankles
    is one of the fe-convergence campaign's FE runs (same key), so once the study has run, every
    such comparison carries its FE's estimated error."""
    from verification.campaigns import ankles, cylinder_plane, fe_convergence, quick, subject, thin_layer

    study = fe_convergence.campaign()
    studied = {fe_key(c.scene, c.sides[-1], c.overrides, c.options) for c in study.cases if len(c.sides) == 1}
    missing = [case.name for module in (quick, subject, cylinder_plane, thin_layer, ankles) for case in module.campaign().cases
               if len(case.sides) > 1 and case.sides[-1].startswith("fe-") and fe_key(case.scene, case.sides[-1], case.overrides, case.options) not in studied]
    assert missing == []
    # the Kelvin-Voigt histories the viscoelastic goal judges (cylinder layer, cartilage ankle) too
    from verification.campaigns import viscoelastic

    goal = [c for c in viscoelastic.campaign().cases if c.name.split("-")[0] in viscoelastic.GOAL_MODELS]
    assert goal and [c.name for c in goal if fe_key(c.scene, c.sides[-1], c.overrides, c.options) not in studied] == []


def test_a_table_gives_the_fe_error_of_the_metrics_it_compares_not_of_the_raw_peak():
    """The tables compare the regularised peak (the raw one is reported only), so the FE's own
    error beside it is the regularised peak's: on the subject-like ankle the two differ by
    tens of percent (the raw peak sits on a rim that does not converge)."""
    from verification.fe_comparison import ERROR_PANELS, FE_ERROR_COLUMNS
    from verification.fe_convergence import fe_error_text

    errors = {"regularised_peak_pressure_rel_error": 0.17, "peak_pressure_rel_error": 0.43,
              "contact_area_rel_error": 0.056, "displacement_rel_error": 0.026, "pressure_l2_rel_error": 0.05}
    assert fe_error_text(errors) == "17.0 % / 5.6 % / 2.6 % / 5.0 %"
    assert [c["fe_error"] for c in FE_ERROR_COLUMNS] == list(ERROR_PANELS)


def test_a_refresh_of_some_points_replaces_their_entries_and_keeps_every_other_point(tmp_path):
    """write_reference merges: a point estimated in the summary replaces its record and all its
    old entries (even under keys it no longer writes) and gets its own date; a point not in the
    summary, or unavailable in it, keeps its stored record, entries and date; a point unavailable
    and not stored gets no record."""
    import json

    from verification.fe_convergence import load_reference, write_reference

    file = tmp_path / "fe_convergence.json"
    old = {"refreshed_at": "2026-11-27T04:20:03+00:00",
           "entries": {"kA-old": {"case": "a-h0.7", "errors": {"x": 0.5}}, "kA-P1": {"case": "a-P1-h1", "errors": {"x": 0.5}},
                       "kB": {"case": "b-h1", "errors": {"x": 0.01}}, "kC": {"case": "c-h1-L4", "errors": {"x": 0.02}}},
           "points": [{"point": "a", "dofs": [1]}, {"point": "b", "dofs": [2]}, {"point": "c", "dofs": [3]}]}
    file.write_text(json.dumps(old))
    summary = {"analyses": [{"kind": "fe-convergence", "values": {
        "entries": {"kA-new": {"case": "a-h1", "errors": {"x": 0.02}}},
        "points": [{"point": "a", "dofs": [10]}, {"point": "c", "unavailable": "case not run"}, {"point": "d", "unavailable": "case not run"}]}}]}
    write_reference(summary, file)
    data = load_reference(file)
    assert set(data["entries"]) == {"kA-new", "kB", "kC"}
    points = {p["point"]: p for p in data["points"]}
    assert points["a"]["dofs"] == [10] and points["a"]["refreshed_at"] == data["refreshed_at"] != old["refreshed_at"]
    assert points["b"] == {"point": "b", "dofs": [2], "refreshed_at": old["refreshed_at"]}
    assert points["c"] == {"point": "c", "dofs": [3], "refreshed_at": old["refreshed_at"]}
    assert "d" not in points


def test_the_fe_of_quicks_ankle_answer_carries_its_own_error_in_the_stored_study():
    """The main job's verdict rests on the two-layer FE of its ankle answer: each of its cases
    finds that FE run's estimated error of the three card metrics in the stored study
    (verification/references/fe_convergence.json), so a change of that FE (level, overrides)
    without a refreshed study fails here instead of turning the answer into "FE error unknown"."""
    from verification.campaigns.quick import answer_cases

    metrics = ("displacement_rel_error", "regularised_peak_pressure_rel_error", "contact_area_rel_error")
    missing = [case.name for case in answer_cases() if not set(metrics) <= set(fe_relative_error(case) or {})]
    assert missing == []


def test_a_goal_judges_a_metric_only_where_the_fe_error_is_known_and_below_it(tmp_path, monkeypatch):
    """The viscoelastic campaign's goal (10 % at every instant): against an FE run in the study, a
    metric whose FE error is below the goal is met or missed on its value; one whose FE error is at
    least the goal is "FE error too large to judge" whatever its value (not a miss, not met); a run
    not in the study has every metric "FE error unknown" and is never counted as met."""
    import json

    from verification import fe_convergence
    from verification.analyses import goal_analysis
    from verification.campaign_model import Analysis
    from verification.campaigns.viscoelastic import GOAL, campaign

    study = campaign()
    coupled, springs = study.case("layer-step-coupled-nu0.42"), study.case("layer-step-springs-nu0.42")
    key = fe_key(coupled.scene, coupled.sides[-1], coupled.overrides, coupled.options)
    file = tmp_path / "fe_convergence.json"
    fe_errors = {"displacement_rel_error": 0.02, "regularised_peak_pressure_rel_error": 0.12, "contact_area_rel_error": 0.01}
    file.write_text(json.dumps({"entries": {key: {"case": "x", "errors": fe_errors}}}))
    monkeypatch.setattr(fe_convergence, "REFERENCE_FILE", file)

    def row(case, errors):
        return {"scene": case.scene, "sides": [{"side": s, "status": "ok"} for s in case.sides], "overrides": case.overrides,
                "options": case.options, "params": case.params, "status": "ran", "metrics": {**errors, "pressure_l2_rel_error": 0.1}}

    errors = {"displacement_rel_error": 0.05, "regularised_peak_pressure_rel_error": 0.30, "contact_area_rel_error": 0.15}
    unstudied = study.case("layer-step-coupled-nu0.3")
    rows = {coupled.name: row(coupled, errors), springs.name: row(springs, errors),
            unstudied.name: row(unstudied, {m: 0.0 for m in errors}), unstudied.name.replace("-coupled-", "-springs-"): row(unstudied, errors)}
    pairs = ((coupled.name, springs.name), (unstudied.name, unstudied.name.replace("-coupled-", "-springs-")))
    result = goal_analysis(Analysis("goal", "goal", "goal", tuple(rows), {**GOAL, "pairs": pairs}), rows)
    judged, unknown = result["values"]["rows"]
    assert judged["misses"] == ["contact area +15.0 % outside ±10 %"]  # the displacement is met; the peak not judged
    assert list(judged["not_judged"]) == ["regularised_peak_pressure_rel_error"] and "too large to judge" in judged["not_judged"]["regularised_peak_pressure_rel_error"]
    assert unknown["misses"] == [] and all("FE error unknown" in why for why in unknown["not_judged"].values()) and len(unknown["not_judged"]) == 3
    assert result["values"]["met"] == 0
    assert result["rows"][1]["cells"][-1].startswith("not judged: ") and not result["rows"][1]["flag"]


def test_every_stored_fe_error_belongs_to_a_run_the_study_makes_today():
    """The stored key leaves out what the scene file already says, so a changed scene default gives
    the same run a new key: the stored entry is then found by no case and its comparisons read "FE
    error unknown" without failing anywhere (67 of them did, 2026-11-28). Every stored entry's key
    and every stored point must be one the fe-convergence study produces now."""
    from verification.campaigns import fe_convergence
    from verification.fe_convergence import _point_of, load_reference

    study = [c for c in fe_convergence.campaign().cases if len(c.sides) == 1]
    keys = {fe_key(c.scene, c.sides[-1], c.overrides, c.options) for c in study}
    stored = load_reference()
    assert [e["case"] for k, e in stored["entries"].items() if k not in keys] == []
    points = {_point_of(c.name) for c in study}
    assert [p["point"] for p in stored["points"] if p["point"] not in points] == []
