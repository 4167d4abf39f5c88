"""Output paths are checked before any solve (exit 2 with a message, the solver never called),
default outputs stay under results/, runs with --set get their own directory, and replacing a
result needs --overwrite."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

import edem.solver
from geometries.errors import InputError
from edem.cli import main
from verification.campaigns import SCENES_DIR

PLATES = str(SCENES_DIR / "flat-plates.toml")


@pytest.fixture
def no_solve(monkeypatch):
    """The solver must not run: every bad path is refused before computing."""

    def refuse(*args, **kwargs):
        raise AssertionError("the solver ran before the output path was checked")

    monkeypatch.setattr(edem.solver, "run", refuse)


def bad_out(tmp_path: Path, kind: str) -> Path:
    if kind == "existing file":
        (tmp_path / "f").write_text("x")
        return tmp_path / "f"
    if kind == "under a file":
        (tmp_path / "f").write_text("x")
        return tmp_path / "f" / "sub" / "out"
    if kind == "name too long":
        return tmp_path / ("n" * 300)
    if kind == "name too long for the temporary sibling":
        return tmp_path / ("n" * 240)
    if kind == "non-result directory":
        (tmp_path / "d").mkdir()
        (tmp_path / "d" / "notes.txt").write_text("mine")
        return tmp_path / "d"
    raise ValueError(kind)


KINDS = ["existing file", "under a file", "name too long", "name too long for the temporary sibling", "non-result directory"]


@pytest.mark.parametrize("kind", KINDS)
def test_run_refuses_a_bad_out_before_solving(tmp_path, capsys, no_solve, kind):
    out = bad_out(tmp_path, kind)
    assert main(["run", PLATES, "--out", str(out), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "edem run: bad input:" in err and "--out" in err
    if kind == "non-result directory":
        assert (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("kind", ["existing file", "under a file", "name too long"])
def test_fe_and_verify_refuse_a_bad_out_before_computing(tmp_path, capsys, monkeypatch, kind):
    import fem_reference.scene_run as scene_run
    import verification.runner as runner

    monkeypatch.setattr(scene_run, "run_scene", lambda *a, **k: pytest.fail("FE solve ran"))
    monkeypatch.setattr(runner, "run_campaign", lambda *a, **k: pytest.fail("campaign ran"))
    out = str(bad_out(tmp_path, kind))
    assert main(["fe", PLATES, "--out", out]) == 2
    assert main(["verify", "quick", "--out", out]) == 2
    err = capsys.readouterr().err
    assert "edem fe: bad input:" in err and "edem verify: bad input:" in err


def test_verify_never_writes_into_a_directory_it_did_not_make(tmp_path, capsys, monkeypatch):
    import verification.runner as runner

    monkeypatch.setattr(runner, "run_campaign", lambda *a, **k: pytest.fail("campaign ran"))
    out = bad_out(tmp_path, "non-result directory")
    assert main(["verify", "quick", "--out", str(out)]) == 2
    assert "holds no 'cases'" in capsys.readouterr().err and sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_another_commands_write_probe_does_not_make_a_directory_foreign(tmp_path):
    """Two campaigns started together: the first one's probe (a hidden directory it makes and
    removes within microseconds) is all the second may see in OUT; it is still OUT's first use."""
    from edem.atomic_dirs import check_out_dir

    out = tmp_path / "out"
    (out / ".probe-abc123").mkdir(parents=True)
    assert check_out_dir(out, reuse_if=("cases", ".lock")) == out
    (out / "notes.txt").write_text("x")
    with pytest.raises(InputError, match="holds no 'cases'"):
        check_out_dir(out, reuse_if=("cases", ".lock"))


@pytest.fixture
def read_only_dir(tmp_path):
    where = tmp_path / "ro"
    where.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(where)], capture_output=True).returncode:
        pytest.skip("mounting a read-only tmpfs needs root")
    yield where
    subprocess.run(["umount", str(where)], check=True)


def test_read_only_file_system_is_refused_before_solving(read_only_dir, capsys, no_solve):
    assert main(["run", PLATES, "--out", str(read_only_dir / "r")]) == 2
    assert "Read-only file system" in capsys.readouterr().err


def scene_named(tmp_path: Path, name: str) -> Path:
    """The flat plates (a built-in geometry: no file references) under another [scene] name."""
    text = Path(PLATES).read_text(encoding="utf-8").replace('name = "flat-plates"', f"name = {json.dumps(name)}", 1)
    path = tmp_path / "odd.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("name", ["../..", "/etc/passwd", "..", "a/../../b"])
def test_default_output_stays_under_results(tmp_path, monkeypatch, capsys, name):
    scene = scene_named(tmp_path, name)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["run", str(scene)]) == 0, capsys.readouterr().err
    made = [p for p in tmp_path.rglob("summary.json")]
    assert len(made) == 1 and made[0].parent.parent == work / "results"


def test_set_without_out_never_reuses_another_runs_directory(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", PLATES]) == 0
    assert main(["run", PLATES, "--set", "cartilage.poissons_ratio=0.3"]) == 0
    assert main(["run", PLATES, "--set", "cartilage.poissons_ratio=0.2"]) == 0
    dirs = sorted(p.name for p in (tmp_path / "results").iterdir())
    assert len(dirs) == 3 and dirs[0] == "flat-plates-dem" and all(d.startswith("flat-plates-dem-set-") for d in dirs[1:])
    summaries = {d: json.loads((tmp_path / "results" / d / "summary.json").read_text()) for d in dirs}
    assert len({s["peak_pressure_mpa"] for s in summaries.values()}) >= 2  # three runs, not one run seen thrice


def test_replacing_a_result_needs_overwrite(tmp_path, capsys):
    out = str(tmp_path / "r")
    assert main(["run", PLATES, "--out", out]) == 0
    first = json.loads((tmp_path / "r" / "manifest.json").read_text())["run_id"]
    assert main(["run", PLATES, "--out", out]) == 2
    assert "a result exists here already" in capsys.readouterr().err
    assert json.loads((tmp_path / "r" / "manifest.json").read_text())["run_id"] == first
    assert main(["run", PLATES, "--out", out, "--overwrite"]) == 0
    assert json.loads((tmp_path / "r" / "manifest.json").read_text())["run_id"] != first
