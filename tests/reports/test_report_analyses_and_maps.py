"""Report extensions: analysis tables (headline numbers, flags), pressure maps at a chosen time
(FE references solved at some instants only), a histogram of wall times for campaigns of
hundreds of cases, and figures of unavailable cases replaced by the reason."""

from __future__ import annotations

import numpy as np
import pytest

from edem.atomic_dirs import write_manifest
from edem.resultdir import read_result_dir, write_surface_frame
from edem.results import write_pvd
from reports.html import _wall_time_figure, write_campaign_report


def _summary(**extra):
    base = {
        "campaign": "synthetic",
        "description": "synthetic",
        "counts": {"verified": 1, "failed": 0, "error": 0, "unavailable": 1},
        "outcomes": {"converges": 2, "refused": 0},
        "finished_at": "now",
        "wall_time_s": 1.0,
        "computed": 2,
        "cached": 0,
        "cases_wall_time_s": 1.0,
        "jobs": 1,
        "versions": {"python": "3"},
        "figures": [],
        "cases": [],
    }
    return {**base, **extra}


def _row(name, status="verified", sides=None, result_dirs=()):
    return {
        "name": name, "description": name, "scene": "s", "scene_description": "", "overrides": {}, "status": status, "outcome": "converges",
        "expected_outcome": None, "metrics": {}, "tolerance": {}, "verdicts": {}, "params": {}, "maps": False, "wall_time_s": 0.1, "cached": False,
        "case_dir": f"cases/{name}", "result_dirs": list(result_dirs), "sides": sides or [{"side": "dem", "status": "ok", "result_dir": None, "message": "", "wall_time_s": 0.1}],
    }


def test_analysis_tables_come_first_with_flagged_rows(tmp_path):
    analysis = {
        "name": "t", "title": "Thesis beside ours", "kind": "thesis", "status": "reported", "columns": ["quantity", "ours", "thesis"],
        "rows": [{"cells": ["peak", "25.9", "7.3"], "flag": True}, {"cells": ["area", "4.47", "4.67"]}], "notes": ["a note"], "values": {},
    }
    unavailable = _row("fe", "unavailable", [{"side": "fe-slab", "status": "unavailable", "result_dir": None, "message": "FE reference not available: test", "wall_time_s": 0.0}])
    figure = {"name": "fe-maps", "title": "FE maps", "kind": "maps", "cases": ["fe"], "instants": [["toe off", "100%"]]}
    path = write_campaign_report(_summary(analyses=[analysis], cases=[unavailable], figures=[figure]), tmp_path)
    text = path.read_text(encoding="utf-8")
    assert text.index("Thesis beside ours") < text.index("<h2>Cases</h2>")
    assert '<tr class="flag"><td>peak</td>' in text and "a note" in text
    assert "FE maps</b>: case fe is unavailable: FE reference not available: test" in text


def test_wall_times_of_hundreds_of_cases_are_a_histogram(tmp_path):
    from matplotlib.image import imread

    rows = [{"name": f"c{i}", "wall_time_s": 0.1 + 0.001 * i, "status": "verified"} for i in range(400)]
    _wall_time_figure(rows, tmp_path / "w.png")
    height, width = imread(tmp_path / "w.png").shape[:2]
    assert height < 600 and width < 1000  # not 400 bars


def _frame_dir(root, times, values):
    """A result directory with a 2-triangle plate whose cell pressure is ``values[k]`` at ``times[k]``."""
    import csv

    from edem.results import TIMESERIES_COLUMNS

    root.mkdir(parents=True)
    (root / "summary.json").write_text('{"scene": "plate", "method": "m"}', encoding="utf-8")
    points = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    with open(root / "timeseries.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(TIMESERIES_COLUMNS)
        for k, t in enumerate(times):
            writer.writerow([k if c == "step" else (t if c == "time_s" else 0.0) for c in TIMESERIES_COLUMNS])
    entries = []
    for k, (t, v) in enumerate(zip(times, values)):
        write_surface_frame(root / f"pressure_{k:04d}.vtp", points, triangles, None, {"pressure_mpa": np.full(2, v), "in_contact": np.ones(2)})
        entries.append((t, f"pressure_{k:04d}.vtp"))
    write_pvd(root / "pressure.pvd", entries)
    write_manifest(root)  # a result directory is sealed by its writer
    return root


def test_pressure_maps_at_a_time_pick_that_map_in_both_directories(tmp_path):
    """a has maps at 0, 1, 2 s; b (an FE at one instant) only at 1 s: time_s = 1 draws a's second
    map against b's only one (a - b = 0: the difference panel is the neutral colour)."""
    from matplotlib.image import imread

    from geometries.errors import InputError
    from reports.maps import _frame_at, render_pressure_maps

    a = _frame_dir(tmp_path / "a", [0.0, 1.0, 2.0], [1.0, 3.0, 9.0])
    b = _frame_dir(tmp_path / "b", [1.0], [3.0])
    assert _frame_at(read_result_dir(a), 1.0).cell_data["pressure_mpa"][0] == 3.0
    with pytest.raises(InputError, match="no pressure map at t = 2"):
        _frame_at(read_result_dir(b), 2.0)
    png = render_pressure_maps(a, b, tmp_path / "m.png", time_s=1.0, title="mid", window_size=(600, 200))
    image = imread(png)[..., :3]
    assert image.shape[:2] == (200, 600)
    centre = [image[80:120, 80 + 200 * k : 120 + 200 * k].reshape(-1, 3).mean(axis=0) for k in range(3)]
    assert np.abs(centre[0] - centre[1]).max() < 0.02  # a (3 MPa at 1 s, not 9 at 2 s) drawn like b
    assert np.abs(centre[2] - centre[2].mean()).max() < 0.05  # a - b = 0: the diverging map's neutral grey


def test_a_sweep_with_series_draws_one_line_per_series_and_goal_lines_on_their_panel(tmp_path, monkeypatch):
    import reports.html as report

    drawn = {}
    monkeypatch.setattr(report, "_save", lambda plt, fig, title, path, axes=None: drawn.update(fig=fig))
    rows = {f"{m}-{nu}": {"params": {"nu": nu}, "metrics": {"a": e * nu, "b": 2 * e * nu}, "tolerance": {}}
            for m, e in (("x", 1.0), ("y", 0.1)) for nu in (0.1, 0.2, 0.3)}
    spec = {"name": "s", "title": "s", "kind": "sweep", "cases": list(rows), "x": "nu", "y": ["a", "b"], "logx": False, "logy": True,
            "series": [["model x", ["x-0.1", "x-0.2", "x-0.3"]], ["model y", ["y-0.1", "y-0.2", "y-0.3"]]], "lines": [["a", 0.05, "goal"]]}
    report._sweep_figure(spec, rows, tmp_path / "s.png")
    panel_a, panel_b = drawn["fig"].axes
    lines_a = {line.get_label(): line for line in panel_a.get_lines()}
    assert set(lines_a) == {"model x", "model y", "goal"} and {line.get_label() for line in panel_b.get_lines()} == {"model x", "model y"}
    assert list(lines_a["model y"].get_ydata()) == pytest.approx([0.01, 0.02, 0.03])


def test_a_sweep_draws_accuracy_tolerances_but_not_sanity_bounds(tmp_path, monkeypatch):
    """A sanity bound (1000 %: a broken run) is no accuracy claim; a model band is drawn."""
    import reports.html as report

    drawn = {}
    monkeypatch.setattr(report, "_save", lambda plt, fig, title, path, axes=None: drawn.update(fig=fig))
    rows = {f"c{nu}": {"params": {"nu": nu}, "metrics": {"a": nu, "b": nu}, "tolerance": {"a": 10.0, "b": 0.5},
                       "verdicts": {"a": {"kind": "sanity"}, "b": {"kind": "model-band"}}} for nu in (0.1, 0.2)}
    spec = {"name": "s", "title": "s", "kind": "sweep", "cases": list(rows), "x": "nu", "y": ["a", "b"], "logx": False, "logy": True}
    report._sweep_figure(spec, rows, tmp_path / "s.png")
    panel_a, panel_b = drawn["fig"].axes
    assert "tolerance" not in {line.get_label() for line in panel_a.get_lines()}
    tolerance = [line for line in panel_b.get_lines() if line.get_label() == "tolerance"]
    assert len(tolerance) == 1 and list(tolerance[0].get_ydata()) == [0.5, 0.5]


def test_the_report_opens_with_its_figures_and_folds_a_long_case_table(tmp_path, monkeypatch):
    """Analyses and figures first, the case table after them, folded when long: the population
    report put 1000 case rows before its distributions."""
    import reports.html as report

    monkeypatch.setattr(report, "_save", lambda plt, fig, title, path, axes=None: fig.savefig(path, dpi=20))
    rows = [{**_row(f"c{i}", result_dirs=[f"cases/c{i}/a-dem"]), "params": {"nu": 0.1 * i}, "metrics": {"peak_pressure_mpa": 1.0 + i}} for i in range(30)]
    figure = {"name": "spread", "title": "peak over the population", "kind": "histogram", "cases": [r["name"] for r in rows], "y": ["peak_pressure_mpa"]}
    analysis = {"name": "t", "title": "A long analysis", "kind": "table", "status": "reported", "columns": ["case"],
                "rows": [{"cells": [r["name"]]} for r in rows], "notes": [], "values": {}}
    text = write_campaign_report(_summary(cases=rows, figures=[figure], analyses=[analysis]), tmp_path).read_text(encoding="utf-8")
    first_figure, cases = text.index('<img src="figures/spread.png"'), text.index("<h2>Cases</h2>")
    assert first_figure < text.index("A long analysis") < cases
    assert text.index("<details>", cases) < text.index("<b>c0</b>")  # 30 rows > LONG_TABLE_ROWS: folded
    assert text.count("<details>") == 2  # the analysis's 30-row table too


def test_axis_labels_are_words_with_units():
    from reports.plots import axis_label

    assert axis_label("a_peak_pressure_mpa") == "peak pressure, side a (MPa)"
    assert axis_label("b_mean_contact_area_mm2") == "mean contact area, side b (mm²)"
    assert axis_label("poissons_ratio") == "Poisson's ratio"
    assert axis_label("displacement_rel_error") == "displacement: relative error (a − b)/|b|"
    assert axis_label("displacement_rel_error", magnitude=True) == "displacement: |relative error|"


def test_a_signed_error_on_a_log_panel_is_drawn_by_its_magnitude(tmp_path, monkeypatch):
    """-59 % is drawn at 0.59 on a log axis (it vanished as a non-positive value), labelled |error|."""
    import reports.html as report

    drawn = {}
    monkeypatch.setattr(report, "_save", lambda plt, fig, title, path, axes=None: drawn.update(fig=fig))
    rows = {f"c{nu}": {"params": {"poissons_ratio": nu}, "metrics": {"displacement_rel_error": -0.59 * nu}, "tolerance": {}} for nu in (0.1, 0.2)}
    spec = {"name": "s", "title": "s", "kind": "sweep", "cases": list(rows), "x": "poissons_ratio", "y": ["displacement_rel_error"], "logx": False, "logy": True}
    report._sweep_figure(spec, rows, tmp_path / "s.png")
    (panel,) = drawn["fig"].axes
    assert list(panel.get_lines()[0].get_ydata()) == pytest.approx([0.059, 0.118])
    assert panel.get_ylabel() == "displacement: |relative error|" and panel.get_xlabel() == "Poisson's ratio"


def test_case_metrics_keep_their_sign_and_grey_what_is_not_judged(tmp_path):
    """-43 % outside the band reads -0.43 (flagged colour); a met sanity bound and a metric set by
    construction are grey "reported, not judged", never green; an FE too coarse has its own class."""
    verdicts = {
        "displacement_rel_error": {"value": -0.43, "tolerance": 0.25, "kind": "model-band", "reason": "band", "verdict": "outside band"},
        "peak_pressure_rel_error": {"value": -0.3, "tolerance": 10.0, "kind": "sanity", "reason": "broken runs", "verdict": "reported, not judged"},
        "contact_area_rel_error": {"value": 0.13, "tolerance": "inf", "kind": "by-construction", "reason": "463 mm^2", "verdict": "reported, not judged"},
        "pressure_l2_rel_error": {"value": 0.2, "tolerance": 0.25, "kind": "model-band", "reason": "band", "verdict": "FE not converged enough to judge", "fe_error": 0.3},
    }
    row = {**_row("slab", "flagged"), "metrics": {m: v["value"] for m, v in verdicts.items()}, "verdicts": verdicts}
    text = write_campaign_report(_summary(cases=[row]), tmp_path).read_text(encoding="utf-8")
    assert '<span class="flagged">displacement_rel_error = -0.43 |·| &gt; band 0.25</span>' in text
    assert '<span class="na">peak_pressure_rel_error = -0.3 (reported, not judged)</span>' in text
    assert '<span class="na">contact_area_rel_error = +0.13 (reported, not judged)</span>' in text
    assert '<span class="fecoarse">pressure_l2_rel_error = 0.2: FE not converged enough to judge' in text
    assert 'class="pass"' not in text
