"""The report's figures fit: a title wraps inside its figure, the legend covers no panel, and the
main job's charts over the load (contact area of DEM and FE, the signed errors) draw each case's
time points."""

from __future__ import annotations

import json

import matplotlib
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from reports.html import _area_load_figure, _per_load_figure  # noqa: E402
from reports.plots import figure_legend, fit_title  # noqa: E402

LOADS = (333.0, 1000.0, 2000.0)


def _extent(fig, artist):
    return artist.get_window_extent(fig.canvas.get_renderer())


@pytest.mark.parametrize("width_in", [4.6, 7.0, 13.8])
def test_a_long_title_wraps_inside_its_figure(width_in):
    fig, ax = plt.subplots(figsize=(width_in, 3.6), constrained_layout=True)
    ax.plot([0, 1], [0, 1])
    title = "contact area (the threshold law's candidates: set by construction): signed error (DEM - FE) / |FE| against Poisson's ratio at 333 N, each bed"
    fit_title(fig, title)
    fig.canvas.draw()
    box, figure_box = _extent(fig, fig._suptitle), fig.bbox
    assert box.x0 >= figure_box.x0 and box.x1 <= figure_box.x1  # no line runs past the edges
    assert fig._suptitle.get_text().replace("\n", " ") == title  # wrapped, not cut
    plt.close(fig)


def test_the_legend_sits_below_the_panels_and_covers_none():
    fig, axes = plt.subplots(1, 3, figsize=(13.8, 4.2), constrained_layout=True, squeeze=False)
    for k, ax in enumerate(axes[0]):
        for j in range(4):
            ax.plot(LOADS, [j + k, j + k + 1, j + k + 2], "o-", label=f"series {j}")
    figure_legend(fig, axes)
    fig.canvas.draw()
    legend = _extent(fig, fig.legends[0])
    assert len(fig.legends[0].get_texts()) == 4  # each label once, for every panel
    for ax in axes[0]:
        assert not legend.overlaps(_extent(fig, ax))
    plt.close(fig)


def _row(tmp_path, name: str, area_dem: list[float], area_fe: list[float], errors: list[float]) -> dict:
    per_time = [{"load_n": f, "contact_area_a_mm2": a, "contact_area_b_mm2": b, "contact_area_rel_error": e}
                for f, a, b, e in zip(LOADS, area_dem, area_fe, errors, strict=True)]
    (tmp_path / "cases" / name).mkdir(parents=True)
    (tmp_path / "cases" / name / "metrics.json").write_text(json.dumps({"comparison": {"per_time": per_time}}))
    return {"out_dir": str(tmp_path), "case_dir": f"cases/{name}", "tolerance": {"contact_area_rel_error": 0.25}}


def test_the_area_against_load_draws_dem_per_bed_and_a_shared_fe_curve_once(tmp_path, monkeypatch):
    rows = {"c": _row(tmp_path, "c", [400, 550, 610], [390, 540, 590], [0.03, 0.02, 0.03]),
            "s": _row(tmp_path, "s", [420, 560, 600], [390, 540, 590], [0.08, 0.04, 0.02])}
    drawn = {}
    monkeypatch.setattr("reports.html._save", lambda plt_, fig, title, path, axes=None: drawn.update(lines=fig.axes[0].get_lines()))
    spec = {"cases": ("c", "s"), "title": "t", "series": (("ideal ankle, coupled layer", ("c",)), ("ideal ankle, independent springs", ("s",)))}
    _area_load_figure(spec, rows, tmp_path / "area.png")
    labels = [line.get_label() for line in drawn["lines"]]
    assert labels == ["ideal ankle, coupled layer: DEM", "ideal ankle: FE", "ideal ankle, independent springs: DEM"]  # the beds share one FE run
    assert [list(line.get_xdata()) for line in drawn["lines"]] == [list(LOADS)] * 3
    assert list(drawn["lines"][0].get_ydata()) == [400, 550, 610]


def test_the_errors_against_load_figure_draws_each_load_and_the_band(tmp_path, monkeypatch):
    rows = {"c": _row(tmp_path, "c", [400, 550, 610], [390, 540, 590], [0.03, -0.02, 0.03])}
    drawn = {}
    monkeypatch.setattr("reports.html._save", lambda plt_, fig, title, path, axes=None: drawn.update(lines=fig.axes[0].get_lines()))
    _per_load_figure({"cases": ("c",), "title": "t", "y": ("contact_area_rel_error",), "series": (("ideal ankle, coupled layer", ("c",)),)}, rows, tmp_path / "e.png")
    by_label = {line.get_label(): line for line in drawn["lines"]}
    assert list(by_label["ideal ankle, coupled layer"].get_ydata()) == [0.03, -0.02, 0.03]  # signed, at each load
    assert sorted(set(by_label["model band"].get_ydata())) == [-0.25, 0.25]  # the case's tolerance, both signs


def test_a_figure_over_the_load_without_any_comparison_says_so(tmp_path):
    with pytest.raises(ValueError, match="no case of the figure has a comparison"):
        _area_load_figure({"cases": ("x",), "title": "t", "series": ()}, {"x": {}}, tmp_path / "none.png")


def test_a_discrete_side_is_labelled_by_its_beds_name_not_by_the_keys_value():
    from edem.beds import BEDS
    from reports.html import side_label

    for coupling, bed in BEDS.items():
        row = {"overrides": {"cartilage.coupling": coupling}}
        assert side_label(row, "dem") == f"dem, {bed.label}" and coupling not in side_label(row, "dem")
        assert side_label(row, "fe-two-layer") == "fe-two-layer"  # the FE has no bed
    assert side_label({"overrides": {}}, "edem") == "edem"  # the scene's own bed: not named by the case
