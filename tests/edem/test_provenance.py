"""Reproducible runs: a result directory's resolved scene re-runs to identical numbers, and the
directory records its overrides, the software version and the source revision."""

from __future__ import annotations

import csv
import json
import tomllib

from edem.cli import main
from edem.resultdir import resolved_scene


def _rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.reader(f))


def test_resolved_scene_reruns_to_identical_numbers(tmp_path, capsys):
    first, again = tmp_path / "first", tmp_path / "again"
    assert main(["run", "ideal-standing", "--method", "edem", "--set", "load.force_n=[0.0, 0.0, 500.0]",
                 "--set", "cartilage.poissons_ratio=0.3", "--out", str(first)]) == 0
    summary = json.loads((first / "summary.json").read_text())
    assert summary["overrides"] == {"load.force_n": [0.0, 0.0, 500.0], "cartilage.poissons_ratio": 0.3}
    assert summary["scene_source"] == "ideal-standing"
    assert summary["software_version"] and summary["source_revision"]
    scene = tomllib.loads((first / "scene.toml").read_text())
    assert scene["scene"]["name"] == "ideal-standing" and scene["solver"]["method"] == "edem"
    assert scene["cartilage"]["poissons_ratio"] == 0.3

    # no --method, no --set: everything comes from the resolved scene
    assert main(["run", str(first / "scene.toml"), "--out", str(again)]) == 0
    assert _rows(again / "timeseries.csv") == _rows(first / "timeseries.csv")  # every digit (floats written as repr)
    rerun = json.loads((again / "summary.json").read_text())
    for key in ("scene", "method", "steps", "n_springs", "peak_pressure_mpa", "max_contact_area_mm2", "final_displacement_mm", "max_force_residual_n"):
        assert rerun[key] == summary[key], key
    assert rerun["overrides"] == {}


def test_resolved_scene_makes_file_paths_absolute(tmp_path):
    scene = tmp_path / "mine.toml"
    scene.write_text(
        '[geometry]\nmobile = "meshes/talus.stl"\nfixed = "meshes/tibia.stl"\n'
        "[cartilage]\nyoungs_modulus_mpa = 10.35\npoissons_ratio = 0.42\n"
        '[load]\nfile = "loads.csv"\n',
        encoding="utf-8",
    )
    data = resolved_scene(scene, {"cartilage.poissons_ratio": 0.45}, {"model": "slab", "mesh_size_mm": 1.0})
    assert data["geometry"]["mobile"] == str(tmp_path / "meshes" / "talus.stl")
    assert data["load"]["file"] == str(tmp_path / "loads.csv")
    assert data["scene"]["name"] == "mine"  # the resolved file is scene.toml: the name is pinned
    assert data["cartilage"]["poissons_ratio"] == 0.45
    assert data["fe"] == {"model": "slab", "mesh_size_mm": 1.0}


def test_version_flag_names_version_and_revision(capsys):
    try:
        main(["--version"])
    except SystemExit as exc:
        assert exc.code == 0
    out = capsys.readouterr().out
    assert out.startswith("edem ") and "source " in out
