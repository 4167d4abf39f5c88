"""The fe-analytic campaign: FE problems of the fem_reference core against their closed forms
(Hertz line contact, confined compression), written as result directories (docs/result-format.md), and the
observed convergence orders computed from a mesh sweep (verification/fe_analytic.py,
verification/analyses.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from edem.resultdir import read_result_dir
from verification.analyses import run_analysis
from verification.campaigns import CONFINED_SIZES_MM, HERTZ_SIZES_MM, Analysis, Campaign, get_campaign
from verification.fe_analytic import CONFINED, HERTZ, MATERIAL, half_width_errors, observed_orders, write_exact_result
from reports.html import write_campaign_report
from verification.runner import run_campaign
from verification.sides import side_names


def test_observed_orders_recover_the_exponent_of_synthetic_sweeps():
    """e = C h^p gives p between any meshes; f = f* + C h^p on a constant ratio gives p (Richardson)."""
    h = [0.4, 0.2, 0.1]
    assert observed_orders(h, [3.0 * x**2 for x in h]) == pytest.approx([2.0, 2.0])
    assert observed_orders([1.0, 0.3, 0.1], [x**1.5 for x in (1.0, 0.3, 0.1)]) == pytest.approx([1.5, 1.5])
    assert observed_orders(h, [7.0 + 0.5 * x**3 for x in h], "richardson") == pytest.approx([3.0])
    assert observed_orders(h, [1.0, 2.0, 2.0], "richardson") == [math.inf]
    with pytest.raises(ValueError):
        observed_orders([0.4, 0.2, 0.05], [1.0, 2.0, 3.0], "richardson")  # ratio not constant


def test_exact_hertz_result_directory(tmp_path):
    """p0 = 2 P' / (pi a), a = sqrt(4 P' R / (pi E*)) with E* = E / (1 - nu^2); half model: area a x
    slice, force P' x slice / 2, mean pressure pi p0 / 4; the nodal field is p0 sqrt(1 - x^2/a^2)."""
    size = 0.2
    out = write_exact_result("hertz-line", tmp_path / "hertz", {"mesh_size_mm": size})
    result = read_result_dir(out)
    e_star = MATERIAL["youngs_modulus_mpa"] / (1 - MATERIAL["poissons_ratio"] ** 2)
    load = math.pi * HERTZ.half_width_mm**2 * e_star / (4 * HERTZ.radius_mm)  # P' for a = 1 mm
    a = math.sqrt(4 * load * HERTZ.radius_mm / (math.pi * e_star))
    p0 = 2 * load / (math.pi * a)
    assert a == pytest.approx(HERTZ.half_width_mm, rel=1e-12)
    series = result.timeseries
    assert series["peak_pressure_mpa"][0] == pytest.approx(p0, rel=1e-12)
    assert series["contact_area_mm2"][0] == pytest.approx(a * size, rel=1e-12)
    assert series["force_z_n"][0] == pytest.approx(load * size / 2, rel=1e-12)
    assert series["mean_pressure_mpa"][0] == pytest.approx(math.pi * p0 / 4, rel=1e-12)
    frame = result.frame(0)
    x = frame.points_mm[:, 0]
    assert np.allclose(frame.point_data["pressure_mpa"], p0 * np.sqrt(np.clip(1 - (x / a) ** 2, 0, None)), rtol=1e-12, atol=1e-12)
    assert set(np.unique(frame.points_mm[:, 1])) == {0.0, size}
    assert result.summary["closed_form"]["half_width_mm"] == pytest.approx(a)


def test_exact_confined_compression_result_directory(tmp_path):
    """p = F / A everywhere and d = p h / E' along the load, E' = E (1 - nu) / ((1 + nu)(1 - 2 nu))."""
    result = read_result_dir(write_exact_result("confined-compression", tmp_path / "cc", {"mesh_size_mm": 1.0}))
    e, nu = MATERIAL["youngs_modulus_mpa"], MATERIAL["poissons_ratio"]
    p = CONFINED.load_n / (CONFINED.lx_mm * CONFINED.ly_mm)
    d = p * CONFINED.thickness_mm * (1 + nu) * (1 - 2 * nu) / (e * (1 - nu))
    assert result.timeseries["peak_pressure_mpa"][0] == pytest.approx(p, rel=1e-12)
    assert result.timeseries["disp_z_mm"][0] == pytest.approx(d, rel=1e-12)
    assert np.allclose(result.frame(0).point_data["pressure_mpa"], p)


def test_half_width_errors_read_both_summaries():
    errors = half_width_errors({"fe_problem": {"half_width_mm": 1.05, "half_width_fit_mm": 0.99}}, {"closed_form": {"half_width_mm": 1.0}})
    assert errors == pytest.approx({"half_width_rel_error": 0.05, "half_width_fit_rel_error": 0.01})
    assert half_width_errors({"fe_problem": {}}, {"closed_form": {}}) == {}


def test_fe_analytic_campaign_is_data_with_three_meshes_each():
    campaign = get_campaign("fe-analytic")
    assert {"fe-problem:hertz-line", "closed-form:hertz-line", "fe-problem:confined-compression", "closed-form:confined-compression"} <= set(side_names())
    hertz = [c for c in campaign.cases if c.sides[0] == "fe-problem:hertz-line"]
    confined = [c for c in campaign.cases if c.sides[0] == "fe-problem:confined-compression"]
    assert [c.params["mesh_size_mm"] for c in hertz] == list(HERTZ_SIZES_MM) and len(hertz) == 3
    assert [c.params["mesh_size_mm"] for c in confined] == list(CONFINED_SIZES_MM) and len(confined) == 3
    # tolerances of tests/fem_reference: finest Hertz mesh 1 % (peak) and 2 % (half-width)
    assert hertz[-1].tolerance == {"peak_pressure_rel_error": 0.01, "half_width_rel_error": 0.02}
    # confined compression: the exact solution is in the P2 space (round-off; the Newton solve's 1e-6)
    assert all(c.tolerance["displacement_rel_error"] == 1e-6 and c.bases()["displacement_rel_error"].kind == "closed-form" for c in confined)
    checks = campaign.analyses[0].settings["checks"]
    assert {c["metric"]: c.get("min_order") for c in checks if c.get("min_order")} == {"peak_pressure_rel_error": 1.5, "a_displacement_norm_mm": 1.5}
    assert any(f.kind == "sweep" and f.logx and f.logy for f in campaign.figures)


def _rows(sizes, values, metric="peak_pressure_rel_error", status="verified"):
    return {f"c{i}": {"name": f"c{i}", "params": {"mesh_size_mm": h}, "metrics": {metric: v}, "status": status, "sides": []} for i, (h, v) in enumerate(zip(sizes, values))}


def _order(min_order=None, monotone=False, roundoff=0.0):
    check = {"label": "peak", "cases": ["c0", "c1", "c2"], "x": "mesh_size_mm", "metric": "peak_pressure_rel_error", "mode": "vs-exact"}
    if min_order is not None:
        check.update(min_order=min_order, monotone=monotone)
    return Analysis("orders", "orders", "order", ("c0", "c1", "c2"), {"checks": [check], "roundoff": roundoff})


def test_order_analysis_judges_the_mean_order_and_spots_round_off():
    sizes = [0.4, 0.2, 0.1]
    second = run_analysis(_order(1.5, True), _rows(sizes, [0.016, 0.004, 0.001]))
    assert second["status"] == "verified" and second["values"]["checks"][0]["mean_order"] == pytest.approx(2.0)
    first = run_analysis(_order(1.5, True), _rows(sizes, [0.4, 0.2, 0.1]))
    assert first["status"] == "failed" and first["values"]["checks"][0]["mean_order"] == pytest.approx(1.0)
    not_monotone = run_analysis(_order(0.5, True), _rows(sizes, [0.05, 0.001, 0.002]))  # mean order 2.3, yet it grew
    assert not_monotone["status"] == "failed"
    exact = run_analysis(_order(roundoff=1e-9), _rows(sizes, [1e-15, 3e-13, 1e-12]))
    assert exact["status"] == "reported" and exact["values"]["checks"][0]["verdict"] == "exact"
    unavailable = run_analysis(_order(1.5), _rows(sizes, [None, None, None], status="unavailable"))
    assert unavailable["status"] == "unavailable"


@pytest.mark.fe
def test_fe_confined_compression_case_is_exact_on_a_coarse_mesh(tmp_path):
    """The FE core (P2) on the confined slab: p = F/A and d = p h / E' to round-off (the linear
    solution lies in the FE space), as the quick campaign's FE case runs it."""
    pytest.importorskip("dolfinx_solver")
    case = get_campaign("quick").case(f"fe-confined-compression-h{max(CONFINED_SIZES_MM):g}")
    summary = run_campaign(Campaign("fe", "FE", (case,)), tmp_path / "fe", jobs=1, report=False)
    row = summary["cases"][0]
    assert row["status"] == "verified", row["sides"]
    assert all(v < 1e-9 for v in row["metrics"].values())
    fe = read_result_dir(tmp_path / "fe" / row["result_dirs"][0])
    assert fe.summary["fe_problem"]["element"] == "P2" and fe.summary["n_dofs"] > 0
    assert "pressure_mpa" in fe.frame(0).point_data  # nodal pressure, as `edem fe` writes it


@pytest.mark.slow
@pytest.mark.fe
def test_fe_analytic_campaign_converges_at_the_tested_orders(tmp_path):
    """The whole campaign (about 25 s on 2 cores): every case within its tolerance, the Hertz peak
    pressure and displacement orders above 1.5 (P2), confined compression exact."""
    pytest.importorskip("dolfinx_solver")
    summary = run_campaign(get_campaign("fe-analytic"), tmp_path / "fe-analytic", jobs=2, report=write_campaign_report)
    assert summary["exit_status"] == 0, [(r["name"], r["verdicts"]) for r in summary["cases"] if r["status"] != "verified"]
    checks = {c["metric"] + ":" + c["label"][:5]: c for c in summary["analyses"][0]["values"]["checks"]}
    assert checks["peak_pressure_rel_error:Hertz"]["mean_order"] > 1.5
    assert checks["peak_pressure_rel_error:confi"]["verdict"] == "exact"
    assert (tmp_path / "fe-analytic" / "figures" / "fe-hertz-convergence.png").is_file()
    assert "Observed convergence orders" in (tmp_path / "fe-analytic" / "report.html").read_text()
    assert json.loads((tmp_path / "fe-analytic" / "metrics.json").read_text())["analyses"][0]["status"] == "verified"


def test_exact_two_cylinders_result_directory(tmp_path):
    """Two equal cylinders: E* = E / (2 (1 - nu^2)), R* = R / 2, the load for a = 1 mm is the rigid
    cylinder's (E* and R* both halve); the surface is the upper cylinder's arc, pressed down."""
    from verification.fe_analytic import CYLINDERS

    size = 0.2
    result = read_result_dir(write_exact_result("hertz-cylinders", tmp_path / "cyl", {"mesh_size_mm": size}))
    e_star = MATERIAL["youngs_modulus_mpa"] / (2 * (1 - MATERIAL["poissons_ratio"] ** 2))
    r_star = CYLINDERS.radius_mm / 2
    load = math.pi * CYLINDERS.half_width_mm**2 * e_star / (4 * r_star)
    p0 = 2 * load / (math.pi * CYLINDERS.half_width_mm)
    series = result.timeseries
    assert series["peak_pressure_mpa"][0] == pytest.approx(p0, rel=1e-12)
    assert series["force_z_n"][0] == pytest.approx(-load * size / 2, rel=1e-12)
    assert series["mean_pressure_mpa"][0] == pytest.approx(math.pi * p0 / 4, rel=1e-12)
    x, z = result.frame(0).points_mm[:, 0], result.frame(0).points_mm[:, 2]
    assert np.allclose(x**2 + (z - CYLINDERS.radius_mm) ** 2, CYLINDERS.radius_mm**2)
    assert result.summary["closed_form"]["half_width_mm"] == pytest.approx(CYLINDERS.half_width_mm)


def test_exact_two_layer_confined_result_directory(tmp_path):
    """Two confined layers in series: p = F / A, d = p (h_M / E'_M + h_F / E'_F), M's bone moving down."""
    from verification.fe_analytic import TWO_LAYERS

    result = read_result_dir(write_exact_result("two-layer-confined", tmp_path / "stack", {"mesh_size_mm": 1.0}))
    p = TWO_LAYERS.load_n / (TWO_LAYERS.lx_mm * TWO_LAYERS.ly_mm)

    def confined(e, nu):
        return e * (1 - nu) / ((1 + nu) * (1 - 2 * nu))

    d = p * (TWO_LAYERS.mobile_thickness_mm / confined(MATERIAL["youngs_modulus_mpa"], MATERIAL["poissons_ratio"])
             + TWO_LAYERS.fixed_thickness_mm / confined(*TWO_LAYERS.fixed_material))
    assert result.timeseries["peak_pressure_mpa"][0] == pytest.approx(p, rel=1e-12)
    assert result.timeseries["disp_z_mm"][0] == pytest.approx(-d, rel=1e-12)


def test_fe_two_layers_campaign_is_data_with_three_meshes_each():
    """Three meshes each (ratio 2), tolerances from the two-layer mesh study, minimum orders below the measured ones."""
    from verification.campaigns.fe_two_layers import CYLINDER_SIZES_MM, TWO_LAYER_SIZES_MM

    campaign = get_campaign("fe-two-layers")
    assert {"fe-problem:hertz-cylinders", "closed-form:hertz-cylinders", "fe-problem:two-layer-confined",
            "closed-form:two-layer-confined"} <= set(side_names())
    cylinders = [c for c in campaign.cases if c.sides[0] == "fe-problem:hertz-cylinders"]
    stack = [c for c in campaign.cases if c.sides[0] == "fe-problem:two-layer-confined"]
    assert [c.params["mesh_size_mm"] for c in cylinders] == list(CYLINDER_SIZES_MM)
    assert [c.params["mesh_size_mm"] for c in stack] == list(TWO_LAYER_SIZES_MM)
    assert cylinders[-1].tolerance == {"peak_pressure_rel_error": 0.01, "half_width_rel_error": 0.02}
    assert all(c.tolerance["displacement_rel_error"] == 1e-6 for c in stack)
    checks = campaign.analyses[0].settings["checks"]
    assert {c["metric"]: c.get("min_order") for c in checks if c.get("min_order")} == {
        "a_displacement_norm_mm": 1.5, "peak_pressure_rel_error": 0.5, "half_width_rel_error": 0.7}


@pytest.mark.slow
@pytest.mark.fe
def test_fe_two_layers_campaign_converges_at_the_tested_orders(tmp_path):
    """The whole campaign (about 6 min on 2 shared cores): every case within its tolerance, the
    orders above their minimums, the confined layers exact."""
    pytest.importorskip("dolfinx_solver")
    summary = run_campaign(get_campaign("fe-two-layers"), tmp_path / "fe-two-layers", jobs=2, report=False)
    assert summary["exit_status"] == 0, [(r["name"], r["verdicts"]) for r in summary["cases"] if r["status"] != "verified"]
    analysis = summary["analyses"][0]
    assert analysis["status"] == "verified"
    assert {c["verdict"] for c in analysis["values"]["checks"] if c["label"].startswith("two confined")} == {"exact"}
