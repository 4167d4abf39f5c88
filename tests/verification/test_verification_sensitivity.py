"""The sensitivity campaign (thesis fig. 4.3.10): h_max x ligament modulus over the ideal stance.
Every ligament's modulus is set through an array override (verification.sides), each run writes its
time series without pressure maps (frames "none"), and the relative changes are computed from the grid."""

from __future__ import annotations

import numpy as np
import pytest

from edem.resultdir import read_result_dir
from geometries.errors import InputError
from edem.scene import load_scene
from verification.analyses import grid_of, run_analysis
from verification.campaigns import SCENES_DIR, SENSITIVITY_HMAX_MM, SENSITIVITY_MODULUS_MPA, Analysis, get_campaign, sensitivity_campaign
from reports.html import write_campaign_report
from verification.runner import run_campaign
from verification.sides import expand_array_overrides, run_side


def test_array_overrides_set_every_ligament_or_one():
    every = expand_array_overrides("ideal-stance", {"ligaments[*].youngs_modulus_mpa": 321.0, "cartilage.max_spring_length_mm": 3.0})
    assert every["cartilage.max_spring_length_mm"] == 3.0
    assert [lig["youngs_modulus_mpa"] for lig in every["ligaments"]] == [321.0] * 4
    scene = load_scene("ideal-stance", every)
    assert [lig.youngs_modulus_mpa for lig in scene.ligaments] == [321.0] * 4
    assert scene.cartilage.max_spring_length_mm == 3.0
    one = load_scene("ideal-stance", expand_array_overrides("ideal-stance", {"ligaments[2].area_mm2": 12.0}))
    assert [lig.area_mm2 for lig in one.ligaments] == [10.0, 10.0, 12.0, 10.0]
    assert [lig.name for lig in one.ligaments] == [lig.name for lig in scene.ligaments]
    assert expand_array_overrides("ideal-stance", {"load.force_n": [0, 0, 1]}) == {"load.force_n": [0, 0, 1]}
    with pytest.raises(InputError, match="index 7"):
        expand_array_overrides("ideal-stance", {"ligaments[7].area_mm2": 1.0})
    with pytest.raises(InputError, match="no \\[\\[ligaments\\]\\]"):
        expand_array_overrides(str(SCENES_DIR / "flat-plates.toml"), {"ligaments[*].youngs_modulus_mpa": 1.0})


def test_peak_frames_keep_the_whole_time_series_and_one_map(tmp_path):
    full = run_side("edem", "ideal-stance", {}, tmp_path / "all")
    peak = run_side("edem", "ideal-stance", {}, tmp_path / "peak", {"frames": "peak"})
    a, b = read_result_dir(full.result_dir), read_result_dir(peak.result_dir)
    assert len(b.frames) == 1 and len(a.frames) == len(a.time_s) == len(b.time_s)
    for column in ("peak_pressure_mpa", "contact_area_mm2", "disp_z_mm"):
        assert np.array_equal(a.timeseries[column], b.timeseries[column])
    k = int(np.argmax(a.timeseries["peak_pressure_mpa"]))
    assert b.frames[0][0] == a.time_s[k]
    assert np.array_equal(b.frame(0).cell_data["pressure_mpa"], a.frame(k).cell_data["pressure_mpa"])
    assert b.summary["peak_pressure_mpa"] == a.summary["peak_pressure_mpa"]
    assert run_side("edem", "ideal-stance", {}, tmp_path / "bad", {"frames": "some"}).status == "refused"


def test_no_frames_keep_the_whole_time_series_and_say_so(tmp_path):
    """frames "none": the same summary numbers and time series as a run with every map, a sealed
    directory without the optional surfaces and .sto whose pressure.pvd lists nothing (summary
    pressure_maps = 0), and a reader that refuses to draw a map it does not have (exit-2
    message, not an IndexError)."""
    full = read_result_dir(run_side("edem", "ideal-stance", {}, tmp_path / "all").result_dir)
    bare = read_result_dir(run_side("edem", "ideal-stance", {}, tmp_path / "none", {"frames": "none"}).result_dir)
    assert bare.frames == () and bare.summary["pressure_maps"] == 0 and "pressure_maps" not in full.summary
    assert set(full.timeseries) == set(bare.timeseries)
    for column, values in full.timeseries.items():
        assert np.array_equal(values, bare.timeseries[column]), column
    for key in ("peak_pressure_mpa", "max_contact_area_mm2", "final_displacement_mm", "max_force_residual_n"):
        assert bare.summary[key] == full.summary[key]
    assert {p.name for p in bare.path.iterdir()} == {"summary.json", "scene.toml", "timeseries.csv", "pressure.pvd", "manifest.json"}
    with pytest.raises(InputError, match="without pressure maps"):
        bare.frame(0)


def test_sensitivity_campaign_is_the_thesis_grid():
    campaign = get_campaign("sensitivity")
    assert len(campaign.cases) == 400 and len({c.name for c in campaign.cases}) == 400
    h = sorted({c.params["h_max_mm"] for c in campaign.cases})
    e = sorted({c.params["ligament_modulus_mpa"] for c in campaign.cases})
    assert len(h) == len(e) == 20
    assert (h[0], h[-1]) == SENSITIVITY_HMAX_MM and (e[0], e[-1]) == SENSITIVITY_MODULUS_MPA
    case = campaign.cases[0]
    assert case.overrides["cartilage.max_spring_length_mm"] == case.params["h_max_mm"]
    assert case.overrides["ligaments[*].youngs_modulus_mpa"] == case.params["ligament_modulus_mpa"]
    assert case.expect.outcome == "converges" and case.options == {"frames": "none"}


def _grid_rows(z: np.ndarray, xs, ys):
    rows = {}
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            rows[f"{i}-{j}"] = {"name": f"{i}-{j}", "params": {"h": x, "E": y}, "metrics": {"p": z[i, j]}, "status": "ran", "sides": []}
    return rows


def test_sensitivity_analysis_of_a_hand_grid():
    """p(h, E) = 10 (1 - 0.15 (h - 2.5)) (1 + 0.0002 (E - 200)): -30 % from h 2.5 to 4.5 and +3 %
    from E 200 to 350 at every value of the other, as the thesis reports."""
    xs, ys = np.linspace(2.5, 4.5, 3), np.linspace(200.0, 350.0, 4)
    z = 10.0 * (1 - 0.15 * (xs[:, None] - 2.5)) * (1 + 0.0002 * (ys[None, :] - 200.0))
    rows = _grid_rows(z, xs, ys)
    analysis = Analysis("s", "s", "sensitivity", tuple(rows), {"x": "h", "y": "E", "metric": "p", "thesis_x_change": -0.30, "thesis_y_change": 0.03})
    result = run_analysis(analysis, rows)
    v = result["values"]
    assert v["x_change"]["mean"] == pytest.approx(-0.30) and v["x_change"]["min"] == pytest.approx(-0.30)
    assert v["y_change"]["mean"] == pytest.approx(0.03) and v["y_spread"]["mean"] == pytest.approx(0.03)
    assert not v["x_change"]["flag"] and not v["y_spread"]["flag"] and result["status"] == "reported"
    rows["0-0"]["metrics"]["p"] = 20.0  # h 2.5 at E 200 doubled: that column's change is now -65 %
    again = run_analysis(analysis, rows)["values"]
    assert again["x_change"]["min"] == pytest.approx(z[-1, 0] / 20.0 - 1.0)
    assert grid_of(rows, tuple(rows), "h", "E", "p")[2][0, 0] == 20.0


def test_a_small_sensitivity_grid_end_to_end(tmp_path):
    """3 x 3 runs: the figures are drawn, the changes are those of the cases' peaks, and the
    peak falls as h_max grows (softer springs) at every modulus."""
    summary = run_campaign(sensitivity_campaign(3), tmp_path / "sens", jobs=2, report=write_campaign_report)
    assert summary["exit_status"] == 0, [(r["name"], r["sides"][0]["message"][:200]) for r in summary["cases"] if r["status"] != "ran"]
    rows = {r["name"]: r for r in summary["cases"]}
    xs, ys, z = grid_of(rows, tuple(rows), "h_max_mm", "ligament_modulus_mpa", "a_peak_pressure_mpa")
    assert np.all(np.isfinite(z)) and np.all(np.diff(z, axis=0) < 0)
    values = summary["analyses"][0]["values"]
    assert values["x_change"]["mean"] == pytest.approx(np.mean((z[-1] - z[0]) / z[0]))
    assert values["y_change"]["mean"] == pytest.approx(np.mean((z[:, -1] - z[:, 0]) / z[:, 0]))
    for name in ("sensitivity-heatmap", "sensitivity-cuts"):
        assert (tmp_path / "sens" / "figures" / f"{name}.png").is_file()
    text = (tmp_path / "sens" / "report.html").read_text(encoding="utf-8")
    assert "change of the peak, h_max_mm 2.5 -&gt; 4.5" in text and "not drawn" not in text
