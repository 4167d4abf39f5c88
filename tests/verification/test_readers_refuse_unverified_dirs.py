"""`edem compare` and `edem plot` read only result directories that verify against their
manifest: a stale file of an earlier run, a summary from another run, a truncated file or a
directory without a manifest is bad input (exit 2) naming the directory, never read."""

from __future__ import annotations

import json
import shutil

import pytest

from edem.cli import main
from verification.campaigns import SCENES_DIR

PLATES = str(SCENES_DIR / "flat-plates.toml")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    assert main(["run", PLATES, "--method", "dem", "--out", str(root / "dem")]) == 0
    assert main(["run", PLATES, "--method", "edem", "--out", str(root / "edem")]) == 0
    return root


def damaged(runs, tmp_path, how: str):
    target = tmp_path / "damaged"
    shutil.copytree(runs / "dem", target)
    if how == "stale map of an earlier run":
        shutil.copy(target / "pressure_0000.vtp", target / "pressure_0064.vtp")
    elif how == "summary of another run":
        shutil.copy(runs / "edem" / "summary.json", target / "summary.json")
    elif how == "truncated time series":
        data = (target / "timeseries.csv").read_bytes()
        (target / "timeseries.csv").write_bytes(data[: len(data) // 2])
    elif how == "no manifest":
        (target / "manifest.json").unlink()
    return target


HOW = ["stale map of an earlier run", "summary of another run", "truncated time series", "no manifest"]


def test_the_undamaged_directories_compare(runs, tmp_path, capsys):
    assert main(["compare", str(runs / "edem"), str(runs / "dem"), "--out", str(tmp_path / "cmp")]) == 0
    assert json.loads((tmp_path / "cmp" / "metrics.json").read_text())["metrics"]


@pytest.mark.parametrize("how", HOW)
def test_compare_refuses_a_directory_that_does_not_verify(runs, tmp_path, capsys, how):
    bad = damaged(runs, tmp_path, how)
    assert main(["compare", str(runs / "edem"), str(bad), "--out", str(tmp_path / "cmp")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and ("manifest" in err) and "Traceback" not in err
    assert not (tmp_path / "cmp" / "metrics.json").exists()


@pytest.mark.parametrize("how", HOW)
def test_plot_refuses_a_directory_that_does_not_verify(runs, tmp_path, capsys, how):
    bad = damaged(runs, tmp_path, how)
    assert main(["plot", str(bad), "--out", str(tmp_path / "p.png")]) == 2
    assert str(bad) in capsys.readouterr().err and not (tmp_path / "p.png").exists()


def test_an_empty_map_list_is_read_only_when_the_summary_says_no_maps(tmp_path):
    """pressure.pvd may list no map only in a directory written without maps (summary
    pressure_maps = 0); a sealed directory whose list is empty for another reason is refused."""
    from edem.atomic_dirs import write_manifest
    from geometries.errors import InputError
    from edem.resultdir import read_result_dir, timeseries_row, write_result_dir

    row = timeseries_row(0, 0.0, [0.0, 0.0, 1.0], 1.0, 1.0, 1.0, [0.0] * 3, [0.0] * 3, 1, 0.0)
    summary = {"scene": "s", "method": "edem", "steps": 1, "wall_time_s": 0.0, "peak_pressure_mpa": 1.0,
               "max_contact_area_mm2": 1.0, "final_displacement_mm": [0.0] * 3, "max_force_residual_n": 0.0, "warnings": []}
    out = write_result_dir(tmp_path / "bare", summary, [row], [])
    assert read_result_dir(out).frames == ()
    (out / "summary.json").write_text(json.dumps(summary), encoding="utf-8")  # the key gone, then sealed again
    write_manifest(out)
    with pytest.raises(InputError, match="lists no data set"):
        read_result_dir(out)
