"""The population campaign (issue 13): seeded subjects, their metrics, a Dask run of the same cases."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from geometries.builders import SUBJECT_RANGES, SUBJECT_THESIS_ONLY
from verification.campaigns import get_campaign, population
from verification.runner import run_campaign


def test_population_is_seeded_and_inside_the_anatomical_ranges():
    first, again = population.population_parameters(50), population.population_parameters(50)
    assert first == again  # the same population on every machine
    for subject in first:
        # every range but the thesis geometry's plafond gap: the subjects carry cartilage, the tibia placed touching
        assert set(subject) == set(SUBJECT_RANGES) - set(SUBJECT_THESIS_ONLY)
        for name, value in subject.items():
            low, high = SUBJECT_RANGES[name]
            assert low <= value <= high
    radii = np.array([s["talar_radius_mm"] for s in first])
    assert radii.std() > 0.2 * (SUBJECT_RANGES["talar_radius_mm"][1] - SUBJECT_RANGES["talar_radius_mm"][0]) / np.sqrt(12)
    assert len(get_campaign("population").cases) == population.POPULATION_SIZE


def _metrics(summary: dict) -> dict[str, dict[str, float]]:
    return {c["name"]: c["metrics"] for c in summary["cases"]}


def test_population_cases_solve_and_their_centre_of_pressure_lies_on_the_talus(tmp_path):
    """Every subject solves its stance; the stance-mean centre of pressure lies within the talar
    dome's half width (ML, x) and its arc (AP, y), as a weighted mean of spring centroids must."""
    summary = run_campaign(population.campaign(3), tmp_path / "pop", jobs=1, report=False)
    assert summary["exit_status"] == 0
    outcomes = {c["name"]: c["outcome"] for c in summary["cases"]}
    for case in population.campaign(3).cases:
        m = _metrics(summary)[case.name]
        assert outcomes[case.name] == "converges"
        assert m["a_peak_pressure_mpa"] > 0 and m["a_mean_contact_area_mm2"] > 0
        assert abs(m["a_cop_x_mm"]) <= 0.5 * case.params["talar_width_mm"]
        assert abs(m["a_cop_y_mm"]) <= case.params["talar_radius_mm"]
        series = (tmp_path / "pop").rglob("timeseries.csv")
        assert any("cop_y_mm" in p.read_text().splitlines()[0] for p in series)


def test_population_on_a_dask_cluster_gives_the_same_metrics(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    local = run_campaign(population.campaign(2), tmp_path / "local", jobs=1, report=False)
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1, dashboard_address=None) as cluster:
        remote = run_campaign(population.campaign(2), tmp_path / "dask", scheduler=cluster.scheduler_address, report=False)
    assert remote["computed"] == 2 and remote["exit_status"] == 0
    # Same inputs, same code, same machine: bit-identical numbers whoever runs them.
    assert _metrics(remote) == _metrics(local)
    assert json.loads(Path(tmp_path / "dask" / "metrics.json").read_text())["scheduler"] == cluster.scheduler_address


def test_population_coupled_runs_the_same_subjects_on_the_coupled_layer(tmp_path):
    """The coupled campaign's subjects are the population's (same seeded geometry), every one
    solves its stance on the coupled layer (the resolved scene says so), and its centre of
    pressure lies on the talus as a weighted mean of spring centroids must."""
    from verification.campaigns import population_coupled

    coupled, springs = population_coupled.campaign(2), population.campaign(2)
    assert [c.params for c in coupled.cases] == [c.params for c in springs.cases]
    summary = run_campaign(coupled, tmp_path / "pop", jobs=1, report=False)
    assert summary["exit_status"] == 0
    for case in coupled.cases:
        m = _metrics(summary)[case.name]
        assert m["a_peak_pressure_mpa"] > 0 and abs(m["a_cop_x_mm"]) <= 0.5 * case.params["talar_width_mm"]
        resolved = tomllib.loads((tmp_path / "pop" / "cases" / case.name / "a-edem" / "scene.toml").read_text())
        assert resolved["cartilage"]["coupling"] == "thin-layer"
