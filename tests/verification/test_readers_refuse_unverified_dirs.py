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
